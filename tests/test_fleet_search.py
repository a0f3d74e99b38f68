"""The fleet's shared search (``missions.fleet_search``), its planner (``missions.searchers.fleet``), its decision
rounds (``SearchPilot.decide_round``) and the separation shield and watch (``autonomy.separation``), without
MAVLink: a one-drone fleet is the single-drone search, looks multiply on one map, sightings and close looks are
shared, drones split the water and the candidates, the find ends every drone's search, and the shield takes out
what would close on another drone."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from autonomy.pilots import ScriptedPilot
from autonomy.search_pilot import SearchPilot
from autonomy.separation import Position, Separation, SeparationWatch, separated_velocity
from autonomy.setpoints import VelocityCommand
from missions import belief as belief_logic
from missions import search
from missions.fleet import Fleet, FleetVehicle
from missions.fleet_search import FleetSearchState, drone_seed
from missions.goals import cell_centres
from missions.mission_file import load_mission
from missions.search_state_v1 import CONFIRMED, NONE, UNRESOLVED
from missions.searchers.fleet import FleetGreedyBayes
from simulation.fleet_replay import fly_exactly

FLEET_DEMO = "missions/library/fleet-demo.yaml"


def fleet_of(count: int, spacing_m: float = 40.0):
    mission = load_mission(FLEET_DEMO)
    vehicles = tuple(FleetVehicle(f"drone{i + 1}", i + 1, 0.0, i * spacing_m) for i in range(count))
    return dataclasses.replace(mission, fleet=Fleet(vehicles, separation_m=30.0, altitude_layer_m=10.0))


def test_a_one_drone_fleet_is_the_single_drone_search():
    mission = fleet_of(1)
    single = SearchPilot(dataclasses.replace(mission, fleet=None), ScriptedPilot("greedy_bayes"), seed=5)
    fleet = SearchPilot(mission, ScriptedPilot("greedy_bayes"), seed=5, state=FleetSearchState(mission, 5))
    position = single.state.scen.start[0].copy()
    for _ in range(150):
        one = single.decide(position)
        two = fleet.decide_round(position[None], np.ones(1, dtype=bool))[0]
        assert one == two
        if one.end is not None:
            break
        position = position + np.array(one.velocity_ne) * mission.flight.step_period_s
    assert np.array_equal(single.state.belief, fleet.state.belief)
    assert drone_seed(5, 0) == np.uint64(5)


def test_every_look_lowers_the_one_shared_map_and_each_drone_has_its_layer():
    mission = fleet_of(3)
    state = FleetSearchState(mission, seed=1)
    assert state.search_altitude_m.tolist() == [50.0, 60.0, 70.0]
    assert len(set(state.episode_seed.tolist())) == 3  # each drone its own detection draws
    datum = state.scen.datum[0]
    positions = datum + np.array([[0.0, 0.0], [120.0, 0.0], [0.0, 120.0]])
    state.position[:] = positions
    expected_belief, expected_coverage = state.belief[:1].copy(), state.coverage[:1].copy()
    # the same step on a copy of the map, the three looks applied one after the other
    drift_offset = state.belief_offset[:1].copy()
    belief_logic.drift((expected_belief, expected_coverage), drift_offset, state.scen.area[:1],
                       state.scen.forecast_drift[:1], 1.0)
    out = state.advance(positions, np.ones(3), np.zeros(3), 1.0)
    size_m = search.OBJECT_SIZE_M[state.scen.target_category[0:1, state.scen.primary_index[0]]]
    for row in range(3):
        belief_logic.look(expected_belief, expected_coverage, state.scen.area[:1], drift_offset, positions[row:row + 1],
                          state.altitude[row:row + 1], np.zeros(1), np.ones(1), size_m,
                          state.scen.detection_factor[0:1, state.scen.primary_index[0]])
    for row in range(3):
        assert np.allclose(state.belief[row], expected_belief[0], rtol=0, atol=1e-15)
        assert np.array_equal(state.coverage[row], state.coverage[0])
    assert np.all(out.belief_removed > 0.0)
    assert state.belief[0].sum() == pytest.approx(1.0 - out.belief_removed.sum(), abs=1e-12)


def test_a_sighting_and_a_close_look_by_one_drone_are_every_drones():
    mission = fleet_of(3)
    state = FleetSearchState(mission, seed=3)
    victim = state.scen.primary_index[0]
    sighted = np.zeros((3, state.max_targets), dtype=bool)
    sighted[1, victim] = True  # drone 2 alone sees the victim's category there
    state._update_candidates(sighted, np.ones(3), np.zeros(3), 1.0)
    assert state.status[:, victim].tolist() == [UNRESOLVED] * 3
    assert np.all(state.sighting[:, victim] == state.targets[1, victim])
    assert state._new_candidate.all()  # a decision event for every drone
    # drone 3 hovers on the victim at the close-look altitude until it is identified; the others fly elsewhere
    state.position[:] = state.targets[:, victim]
    state.position[[0, 1]] += 300.0
    state.altitude[:] = 20.0
    state.speed_mps[:] = 0.0
    for _ in range(200):
        state._update_candidates(np.zeros_like(sighted), np.ones(3), np.full(3, 0.5), 1.0)
        state.time_s += 1.0
        state.steps += 1
        if state.status[0, victim] == CONFIRMED:
            break
    assert state.status[:, victim].tolist() == [CONFIRMED] * 3
    assert np.all(state.status[:, [t for t in range(state.max_targets) if t != victim]] == NONE)


def test_two_drones_in_one_place_choose_water_apart_and_the_nearest_takes_a_candidate():
    mission = fleet_of(2, spacing_m=30.0)
    state = FleetSearchState(mission, seed=0)
    state.position[:] = state.scen.datum[0]  # both over the datum, where the belief peaks
    planner = FleetGreedyBayes(state)
    grid = state.belief.shape[1]
    north, east = cell_centres(state.scen.area, grid)
    north, east = north + state.belief_offset[:, 0:1], east + state.belief_offset[:, 1:2]
    cells = planner.choose_cells(np.arange(2), north, east)
    points = [(north[r, c // grid], east[r, c % grid]) for r, c in zip(range(2), cells)]
    assert np.hypot(points[0][0] - points[1][0], points[0][1] - points[1][1]) > planner.claim_radius_m
    # alone (the other drone out of the search), drone 2 takes the best cell itself
    state.searching[:] = [False, True]
    alone = planner.choose_cells(np.array([1]), north, east)[0]
    assert alone == cells[0]
    state.searching[:] = True
    worth = np.zeros((2, state.max_targets), dtype=bool)
    worth[:, 0] = True
    state._estimates = state._estimates.copy()
    state._estimates[:, 0] = state.position[1] + [5.0, 0.0]
    state.position[0] += [400.0, 0.0]
    assert planner.own_candidates(worth)[:, 0].tolist() == [False, True]


@pytest.mark.parametrize("pilot", ["greedy_bayes", "expanding_square"])
def test_the_find_ends_every_drones_search(pilot):
    mission = fleet_of(3)
    pilot_ = SearchPilot(mission, ScriptedPilot(pilot), seed=0, state=FleetSearchState(mission, 0))
    ends = fly_exactly(pilot_)
    assert "victim reached" in ends
    # in the round of the find, every drone still searching ends too (an uncoordinated pattern may bring several
    # drones to the victim in the same round)
    assert set(ends) <= {"victim reached", "victim reached by another drone"}
    assert not pilot_.live.any()


def test_more_drones_find_sooner_on_the_same_seeds():
    """Sequential greedy on the shared map: the median steps to the end of the search fall with the fleet's
    size and no seed is lost by adding drones (same seeds, exact flight)."""
    medians, finds = [], []
    for count in (1, 3):
        mission = fleet_of(count)
        steps, found = [], 0
        for seed in range(4):
            pilot = SearchPilot(mission, ScriptedPilot("greedy_bayes"), seed=seed,
                                state=FleetSearchState(mission, seed))
            ends = fly_exactly(pilot)
            steps.append(int(pilot.state.steps[0]))
            found += "victim reached" in ends
        medians.append(float(np.median(steps)))
        finds.append(found)
    assert medians[1] < 0.8 * medians[0]
    assert finds[1] >= finds[0]


RULE = Separation(horizontal_m=30.0, vertical_m=5.0, lookahead_s=2.0)


def test_the_shield_takes_out_closing_velocity_and_pushes_apart_inside_the_separation():
    own = Position("a", 0.0, 0.0, 50.0)
    ahead = Position("b", 40.0, 0.0, 50.0)  # 40 m north, same height: inside the 30 + 2 x 10 m guard
    shielded = separated_velocity(own, VelocityCommand(10.0, 3.0, 0.0), [ahead], RULE, 10.0)
    assert shielded.vn == pytest.approx(0.0) and shielded.ve == pytest.approx(3.0)
    # moving away is left alone
    assert separated_velocity(own, VelocityCommand(-10.0, 0.0, 0.0), [ahead], RULE, 10.0) == \
        VelocityCommand(-10.0, 0.0, 0.0)
    inside = Position("b", 20.0, 0.0, 50.0)
    pushed = separated_velocity(own, VelocityCommand(0.0, 0.0, 0.0), [inside], RULE, 10.0)
    assert pushed.vn < 0.0
    # far away, on the ground, or on another layer: no change horizontally
    for other in (Position("b", 200.0, 0.0, 50.0), Position("b", 20.0, 0.0, 0.0, airborne=False),
                  Position("b", 20.0, 0.0, 60.0)):
        assert separated_velocity(own, VelocityCommand(10.0, 0.0, 0.0), [other], RULE, 10.0).vn == 10.0


def test_the_shield_stops_a_descent_onto_a_drone_below_but_not_a_climb_away():
    own = Position("a", 0.0, 0.0, 60.0)
    below = Position("b", 10.0, 0.0, 53.5)  # 6.5 m below, horizontally close: separated by height, just
    assert separated_velocity(own, VelocityCommand(0.0, 0.0, 1.5), [below], RULE, 10.0).vd == 0.0
    assert separated_velocity(own, VelocityCommand(0.0, 0.0, -1.5), [below], RULE, 10.0).vd == -1.5


def test_the_watch_counts_each_breach_once_and_the_closest_approach_on_one_layer():
    watch = SeparationWatch(RULE)
    a = Position("a", 0.0, 0.0, 50.0)
    watch.observe(0.0, [a, Position("b", 50.0, 0.0, 50.0)])
    watch.observe(1.0, [a, Position("b", 20.0, 0.0, 60.0)])  # close, but a layer apart: separated
    watch.observe(2.0, [a, Position("b", 25.0, 0.0, 52.0)])  # breach
    watch.observe(3.0, [a, Position("b", 22.0, 0.0, 51.0)])  # the same breach
    watch.observe(4.0, [a, Position("b", 40.0, 0.0, 50.0)])
    watch.observe(5.0, [a, Position("b", 10.0, 0.0, 0.5, airborne=False)])  # landed: not counted
    summary = watch.summary()
    assert summary["breached"] and len(summary["breaches"]) == 1
    assert summary["breaches"][0] == {"time_s": 2.0, "drones": ["a", "b"], "horizontal_m": 25.0, "vertical_m": 2.0}
    assert summary["closest_unlayered_m"] == 22.0


def test_a_drone_landing_through_the_layer_counts_as_not_separated_by_height():
    """A drone 15 m above, descending at 2 m/s (an autopilot's RTL landing at its home: not shielded), will be on
    this drone's height within 10 s: this drone stops closing on it horizontally. Hovering there, it would not."""
    own = Position("a", 0.0, 0.0, 50.0)
    landing = Position("b", 40.0, 0.0, 65.0, vup_mps=-2.0)
    assert separated_velocity(own, VelocityCommand(10.0, 0.0, 0.0), [landing], RULE, 10.0).vn == pytest.approx(0.0)
    hovering = Position("b", 40.0, 0.0, 65.0)
    assert separated_velocity(own, VelocityCommand(10.0, 0.0, 0.0), [hovering], RULE, 10.0).vn == 10.0
