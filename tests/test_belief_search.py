"""SarSearch-v1's search logic (``missions.belief``, ``missions.search_state_v1``): the belief's prior, looks, drift
and blur; candidates, close looks and the confirmation rule; the endurance and the return home."""
from __future__ import annotations

import math

import numpy as np
import pytest

from missions import belief
from missions.search_state_v1 import (
    BINGO_RESERVE_S,
    CLOSE_LOOK_ALTITUDE_M,
    CONFIRMED,
    DESCENT_MPS,
    LOST,
    REJECTED,
    TARGET_SLOTS,
    UNRESOLVED,
    BeliefSearchState,
)
from missions.coverage import GRID_SIZE
from missions.goals import TRACK_OBJECT
from missions.mission import FlightSettings
from missions.scenario import Conditions, Scenario, SearchArea, Target
from missions.search import OBJECT_SIZE_M, RESOLUTION_SCALE, ScenarioBatch

AREA = SearchArea(-50.0, 950.0, -500.0, 500.0)
CELL_M = 1000.0 / GRID_SIZE
FLIGHT = FlightSettings()


def state_for(victim=(600.0, 100.0), decoys=(), datum=(550.0, 80.0), endurance_s=None, **scenario) -> BeliefSearchState:
    targets = (Target("person", *victim, primary=True),) + tuple(Target("person", *d) for d in decoys)
    s = Scenario(area=AREA, datum_north_m=datum[0], datum_east_m=datum[1], datum_sigma_m=80.0, targets=targets,
                 endurance_s=endurance_s, conditions=Conditions(), **scenario)
    state = BeliefSearchState(ScenarioBatch.from_scenarios([s], num_targets=TARGET_SLOTS), FLIGHT)
    state.reset(np.array([0]), np.array([5], dtype=np.uint64))
    return state


def hover(state: BeliefSearchState, at, steps: int, intensity=1.0, zoom=0.0):
    outcomes = []
    for _ in range(steps):
        outcomes.append(state.advance(np.array([at], dtype=float), np.array([intensity]), np.array([zoom]), 1.0))
    return outcomes


def hover_until_sighted(state: BeliefSearchState, at, slot: int, steps: int = 10) -> None:
    """Hover (zoomed out) until the object in ``slot`` is a candidate: a sighting is a draw, about 3 in 4 a step."""
    for _ in range(steps):
        hover(state, at, 1)
        if state.status[0, slot] == UNRESOLVED:
            return
    raise AssertionError(f"slot {slot} not sighted in {steps} steps")


# ------------------------------------------------------------------------------------------------ the belief


def test_prior_sums_to_one_and_peaks_in_the_datums_cell():
    area = np.array([[-50.0, 950.0, -500.0, 500.0]])
    grid = belief.prior(area, np.array([[550.0, 80.0]]), np.array([80.0]), GRID_SIZE)
    assert grid.sum() == pytest.approx(1.0)
    row, col = np.unravel_index(grid[0].argmax(), grid[0].shape)
    assert (row, col) == (int((550.0 + 50.0) // CELL_M), int((80.0 + 500.0) // CELL_M))


def test_the_prior_holds_each_cells_integral_and_the_edge_cells_what_lies_beyond():
    area = np.array([[0.0, 1000.0, 0.0, 1000.0]])
    datum, sigma = np.array([[60.0, 500.0]]), np.array([100.0])  # a datum near the south edge: a fifth lies beyond
    grid = belief.prior(area, datum, sigma, GRID_SIZE)[0]

    def normal_cdf(x):
        return 0.5 * (1.0 + math.erf((x - 60.0) / (100.0 * math.sqrt(2.0))))

    north = grid.sum(axis=1)  # the east part sums to one over the rows
    assert north[5] == pytest.approx(normal_cdf(6 * CELL_M) - normal_cdf(5 * CELL_M), rel=1e-9)
    assert north[0] == pytest.approx(normal_cdf(CELL_M), rel=1e-9)  # the first cell and everything south of it
    assert grid.sum() == pytest.approx(1.0)


def test_a_look_lowers_the_cell_under_the_drone_by_its_detection_probability_averaged_over_the_cell():
    state = state_for()
    row, col = 10, 20
    centre = np.array([-50.0 + (row + 0.5) * CELL_M, -500.0 + (col + 0.5) * CELL_M])
    before = state.belief[0, row, col]
    out = hover(state, centre, 1)[0]
    # The whole cell (31.25 m) lies in the 70 m footprint: f_range averaged over a square of side c centred below
    # the drone is 1 - 0.5 * (c^2 / 12 + c^2 / 12) / h^2; the person's resolution term at 50 m, zoom 0, calm clear day.
    h = 50.0 * math.tan(math.radians(35.0))
    p = 0.98 * (1.0 - math.exp(-OBJECT_SIZE_M[0] * RESOLUTION_SCALE / 50.0)) * (1.0 - CELL_M ** 2 / (12.0 * h ** 2))
    assert state.belief[0, row, col] == pytest.approx(before * (1.0 - p))
    assert state.coverage[0, row, col] == pytest.approx(p)
    assert out.belief_removed[0] > before * p  # the neighbouring cells of the 70 m footprint lost some too
    far = state_for()
    hover(far, centre, 1, intensity=0.0)  # the sensor off: nothing searched
    assert far.belief[0, row, col] == pytest.approx(before) and far.coverage.sum() == 0.0


def test_the_belief_drifts_with_the_forecast_by_whole_cells():
    state = state_for(current_north_mps=0.0, current_east_mps=0.25, forecast_current_north_mps=0.0,
                      forecast_current_east_mps=0.5)
    start = state.belief[0].copy()
    seconds = int(math.ceil(CELL_M / 0.5))  # the forecast (not the true 0.25 m/s) moves the map
    hover(state, (0.0, 0.0), seconds - 1, intensity=0.0)
    assert state.belief_offset[0, 1] == pytest.approx((seconds - 1) * 0.5)
    hover(state, (0.0, 0.0), 1, intensity=0.0)
    shifted = state.belief[0]
    assert state.belief_offset[0, 1] == pytest.approx(seconds * 0.5 - CELL_M)
    # one cell east (up to the blur that the forecast's growing error adds every 30 s)
    assert np.unravel_index(shifted.argmax(), shifted.shape)[1] == np.unravel_index(start.argmax(), start.shape)[1] + 1
    assert shifted.sum() == pytest.approx(start.sum(), rel=1e-5)  # the prior's far tail drifted off the area


def test_the_blur_keeps_the_mass_and_adds_the_asked_variance():
    grid = np.zeros((1, GRID_SIZE, GRID_SIZE))
    grid[0, 16, 16] = 1.0
    belief.blur(grid, np.array([[0.3, 1.2]]))
    assert grid.sum() == pytest.approx(1.0)
    rows, cols = np.arange(GRID_SIZE) - 16.0, np.arange(GRID_SIZE) - 16.0
    assert (grid[0].sum(axis=1) * rows ** 2).sum() == pytest.approx(0.3)
    assert (grid[0].sum(axis=0) * cols ** 2).sum() == pytest.approx(1.2)
    edge = np.zeros((1, GRID_SIZE, GRID_SIZE))
    edge[0, 0, 0] = 1.0
    belief.blur(edge, np.array([[0.4, 0.4]]))
    assert edge.sum() == pytest.approx(1.0)  # nothing spreads off the grid


# ------------------------------------------------------------------------------------------- the candidates


def test_a_decoy_becomes_a_candidate_and_a_close_look_rejects_it():
    state = state_for(decoys=[(300.0, -200.0)])
    hover_until_sighted(state, (300.0, -200.0), 1)
    assert state.status[0, 1] == UNRESOLVED and state.status[0, 0] == 0  # sighted, not yet told apart
    assert state.candidate_kind()[0, 1] == 1
    # what TrackObject flies to is the decoy: nothing in the search logic knows it is not the victim
    np.testing.assert_allclose(state._points(np.array([TRACK_OBJECT]), np.array([True]))[0],
                               state.candidate_estimates()[0, 1])
    assert state.close_look()[0] and state.altitude_target[0] == CLOSE_LOOK_ALTITUDE_M
    outcomes = hover(state, (300.0, -200.0), 60, zoom=0.6)
    assert state.status[0, 1] == REJECTED
    assert not any(o.success[0] for o in outcomes)
    assert state.altitude_target[0] == FLIGHT.altitude_m  # resolved: back up to search


def test_the_identify_chance_is_the_identification_probability_at_the_estimate_and_needs_a_slow_drone():
    state = state_for(decoys=[(300.0, -200.0)])
    hover_until_sighted(state, (300.0, -200.0), 1)
    out = hover(state, (300.0, -200.0), 1, zoom=0.6, intensity=0.0)[0]  # sensor off: no chance
    assert out.identify_chance[0] == 0.0
    altitude = state.altitude[0]
    # right over the estimate (the decoy has not moved): f_range = 1, a person's size over 6.4, zoom factor 2.8
    expected = 0.98 * (1.0 - math.exp(-OBJECT_SIZE_M[0] / 6.4 * 2.8 * RESOLUTION_SCALE / (altitude - DESCENT_MPS)))
    out = hover(state, (300.0, -200.0), 1, zoom=0.6)[0]
    assert out.identify_chance[0] == pytest.approx(expected)
    fast = state_for(decoys=[(300.0, -200.0)])
    hover_until_sighted(fast, (300.0, -200.0), 1)
    out = fast.advance(np.array([[300.0, -196.0]]), np.ones(1), np.full(1, 0.6), 1.0)  # 4 m/s: too fast
    assert out.identify_chance[0] == 0.0


def test_the_camera_descends_at_the_descent_rate_for_a_close_look():
    state = state_for(decoys=[(300.0, -200.0)])
    hover_until_sighted(state, (300.0, -200.0), 1)
    assert state.close_look()[0]
    altitude = state.altitude[0]
    hover(state, (300.0, -200.0), 1, zoom=0.0, intensity=0.0)  # sensor off: no identification, keeps looking
    assert state.altitude[0] == pytest.approx(altitude - DESCENT_MPS)


def test_success_needs_the_victim_detected_and_confirmed_not_just_flown_over():
    victim = (600.0, 100.0)
    dark = state_for(victim=victim)
    outcomes = hover(dark, victim, 50, intensity=0.0)  # right over it, sensor off: never detected
    assert not any(o.success[0] for o in outcomes) and dark.status[0, 0] == 0
    fast = state_for(victim=victim)
    for k in range(40):  # across it again and again at 8 m/s: sighted, but never held for a close look
        east = victim[1] + (8.0 if k % 2 else -8.0)
        out = fast.advance(np.array([[victim[0], east]]), np.ones(1), np.full(1, 0.6), 1.0)
        assert not out.success[0]
    assert fast.status[0, 0] == UNRESOLVED
    slow = state_for(victim=victim)
    outcomes = hover(slow, victim, 60, zoom=0.6)
    assert slow.status[0, 0] == CONFIRMED and any(o.success[0] for o in outcomes)


def test_a_candidate_hovered_over_but_not_seen_is_lost_until_sighted_again():
    state = state_for(decoys=[(300.0, -200.0)])
    hover_until_sighted(state, (300.0, -200.0), 1)
    state.targets[0, 1] += (200.0, 0.0)  # it moved away unseen (a forecast far off)
    hover(state, (300.0, -200.0), 25, zoom=0.6)
    assert state.status[0, 1] == LOST and state.candidate_kind()[0, 1] == 0
    hover_until_sighted(state, tuple(state.targets[0, 1]), 1)


def test_a_sightings_plausibility_is_its_cells_belief_over_the_best_cells_then():
    state = state_for(decoys=[(560.0, 70.0), (100.0, -400.0)])  # one by the datum (550, 80), one far from it
    for slot, at in ((1, (560.0, 70.0)), (2, (100.0, -400.0))):
        for _ in range(10):
            before, offset = state.belief[0].copy(), state.belief_offset[0].copy()
            hover(state, at, 1)
            if state.status[0, slot] == UNRESOLVED:
                break
        row, col = (np.array(at) - (-50.0, -500.0) - offset) // CELL_M
        assert state.plausibility[0, slot] == pytest.approx(before[int(row), int(col)] / before.max())
    assert state.plausibility[0, 1] > 100 * state.plausibility[0, 2]


# ---------------------------------------------------------------------------------- endurance and home


def test_the_endurance_runs_out_and_coming_home_ends_the_sortie():
    dry = state_for(endurance_s=30.0)
    outcomes = hover(dry, (200.0, 0.0), 30, intensity=0.0)
    assert [o.ran_dry[0] for o in outcomes].index(True) == 29  # the 30th second
    assert dry.energy_left[0] == 0.0
    home = state_for(endurance_s=600.0)
    assert not hover(home, (0.0, 0.0), 1)[0].returned[0]  # hovering at home before leaving it is not a return
    hover(home, (100.0, 0.0), 1)
    assert not hover(home, (8.0, 0.0), 1)[0].returned[0]  # over home at 92 m/s: passing, not landing
    assert hover(home, (8.0, 0.0), 1)[0].returned[0]


def test_decision_events_ask_for_a_goal_at_once_and_a_decision_restarts_the_clock():
    """A new candidate's sighting and the bingo call (the way home would leave less than the landing reserve) each
    make a goal due before the next step, whatever the K-step clock says; a decision clears the event and restarts
    the clock, so the next periodic decision comes K steps after it. A candidate seen again is not new."""
    state = state_for(decoys=[(200.0, 0.0)], endurance_s=600.0)
    state.set_goals(np.array([TRACK_OBJECT]))
    hover(state, (190.0, 0.0), 3, intensity=0.0)  # sensor off: nothing sighted, the clock runs
    assert state.goal_steps[0] == 3 and not state.goal_due(30)[0]
    hover_until_sighted(state, (190.0, 0.0), slot=1)
    assert state.decision_event[0] and state.goal_due(30)[0]
    state.set_goals(np.array([TRACK_OBJECT]))
    assert not state.decision_event[0] and state.goal_steps[0] == 0
    hover(state, (190.0, 0.0), 29)  # the same candidate, sighted again and again: no new event
    assert not state.goal_due(30)[0]
    hover(state, (190.0, 0.0), 1)
    assert state.goal_due(30)[0] and state.goal_steps[0] == 30  # K steps after the last decision

    far = state_for(endurance_s=600.0)  # 500 m from home is 50 s away: bingo once 20 + 50 s are left
    far.set_goals(np.array([TRACK_OBJECT]))
    seconds_to_bingo = 600.0 - BINGO_RESERVE_S - 500.0 / FLIGHT.max_speed_mps
    for second in range(1, 600):
        hover(far, (500.0, 0.0), 1, intensity=0.0)
        if far.decision_event[0]:
            break
        if far.goal_due(30)[0]:
            far.set_goals(np.array([TRACK_OBJECT]))
    assert second == seconds_to_bingo and far.bingo_margin_s[0] == BINGO_RESERVE_S
    far.set_goals(np.array([TRACK_OBJECT]))
    hover(far, (500.0, 0.0), 5, intensity=0.0)
    assert not far.decision_event[0]  # called once, not at every step below the reserve
