"""The search pilot of the mission runner (``autonomy.search_pilot``) against the environment: for the same flight
it sees what SarSearch-v1 sees, reads ReturnToBase at home as training does, and its bingo failsafe ends a search a
policy would not end in time, as the evaluation's flight rules do."""
from __future__ import annotations

import numpy as np
import pytest

from missions.goals import TRACK_OBJECT
from missions.search_state_v1 import CLOSE_LOOK_ALTITUDE_M
from missions.scenario import Scenario, SearchArea, Target

AREA = SearchArea(-50.0, 950.0, -500.0, 500.0)


class ScriptedArtifact:
    """A stand-in for a loaded artifact (``autonomy.policy.Policy``): TrackObject at every decision, flown
    straight at the observation's target with the camera zoomed in a little."""

    hierarchical, subgoal_interval = True, 30

    def __init__(self, action_frame: str = "north_east"):
        self.seen: list[np.ndarray] = []
        self.action_frame = action_frame  # what an artifact's manifest carries in its training_config

    def attach(self, state) -> None:
        """An artifact acts on the observation alone."""

    def describe(self) -> dict:
        return {"pilot": "scripted artifact"}

    def select_goal(self, meta_obs: np.ndarray) -> np.ndarray:
        return np.full(meta_obs.shape[:-1], TRACK_OBJECT)

    def act(self, obs: np.ndarray) -> np.ndarray:
        self.seen.append(np.array(obs))
        offset = obs[..., 2:4]
        speed = min(1.0, float(np.hypot(*offset)) / 0.5)
        movement = [speed, 0.0] if self.action_frame != "north_east" else offset / max(float(np.hypot(*offset)), 0.5)
        return np.concatenate([movement, [1.0, 0.3]]).astype(np.float32)


@pytest.mark.parametrize("action_frame", ["north_east", "target", "arrive"])
def test_the_pilot_sees_what_the_environment_sees_for_the_same_flight(action_frame):
    from autonomy.search_pilot import SearchPilot
    from missions.mission import Mission
    from policies.env.core import SarSearchConfig
    from policies.env.tasks import make_batch

    scenario = Scenario(area=AREA, datum_north_m=300.0, datum_east_m=50.0, datum_sigma_m=60.0, endurance_s=700.0,
                        targets=(Target("person", 330.0, 80.0, primary=True), Target("person", 250.0, 20.0),
                                 Target("boat", 280.0, -60.0)), name="shared")
    env = make_batch(SarSearchConfig(scenarios=(scenario,), goal_conditioned=True, action_frame=action_frame), [7])
    artifact = ScriptedArtifact(action_frame)
    pilot = SearchPilot(Mission(scenario=scenario), artifact, seed=7)
    env_end = pilot_end = previous = None
    straight_legs = 0
    for step in range(400):
        decision = pilot.decide(env.position[0].copy())
        if env.goal_due(30)[0] and env_end is None:  # every 30 steps and at decision events, as the pilot
            env.set_goals(np.array([TRACK_OBJECT]))
        np.testing.assert_array_equal(artifact.seen[-1], env.obs[0])  # the same observation, value for value
        if decision.end is not None:
            pilot_end = decision.end
            break
        if decision.altitude_m is not None:  # a close look: the runner is asked for the close-look altitude
            assert decision.altitude_m == CLOSE_LOOK_ALTITUDE_M and env.close_look()[0]
        before = env.position[0].copy()
        _, _, terminated, _, info = env.step(np.array([decision.action]))
        # on a straight leg the environment flies the pilot's velocity command's direction
        command, flown = np.array(decision.velocity_ne), env.position[0] - before
        if previous is not None and np.hypot(*command) > 5.0 and np.hypot(*flown) > 5.0:
            turn = np.dot(command, previous) / (np.hypot(*command) * np.hypot(*previous))
            if turn > 0.999:
                straight_legs += 1
                assert np.dot(command, flown) / (np.hypot(*command) * np.hypot(*flown)) > 0.99  # within 8 degrees
        previous = command
        if terminated[0]:
            env_end = "victim reached" if info["success"][0] else "another end"
    assert env_end == pilot_end == "victim reached" and straight_legs > 10


class GoalScript(ScriptedArtifact):
    """ScriptedArtifact with a fixed sequence of goals, one per decision (the last one repeated)."""

    def __init__(self, goals):
        super().__init__("target")
        self.goals, self.decisions = list(goals), 0

    def select_goal(self, meta_obs: np.ndarray) -> np.ndarray:
        goal = self.goals[min(self.decisions, len(self.goals) - 1)]
        self.decisions += 1
        return np.full(meta_obs.shape[:-1], goal)


def test_return_to_base_ends_the_flown_search_only_once_the_drone_has_left_home():
    """In training ReturnToBase at home is a hover until the next decision (the episode's "returned" needs the
    drone to have been away); the pilot and the evaluation's flight rule read it the same way, and end the search
    (the runner's RTL) only when it is chosen away from home."""
    from autonomy.search_pilot import SearchPilot
    from missions.goals import RETURN_TO_BASE
    from missions.mission import Mission

    scenario = Scenario(area=AREA, datum_north_m=300.0, datum_east_m=50.0, datum_sigma_m=60.0, endurance_s=700.0,
                        targets=(Target("person", 330.0, 80.0, primary=True),), name="home-first")
    pilot = SearchPilot(Mission(scenario=scenario), GoalScript([RETURN_TO_BASE, TRACK_OBJECT, RETURN_TO_BASE]), seed=7)
    position, ends = np.zeros(2), []
    for step in range(61):
        decision = pilot.decide(position.copy())
        ends.append(decision.end)
        if decision.end is not None:
            break
        position = position + np.array(decision.velocity_ne) * 1.0  # flown exactly, 1 s per step
        if step < 30:
            assert np.hypot(*position) < 1.0  # ReturnToBase at home: a hover over home
    assert ends[:60] == [None] * 60  # the first ReturnToBase (at home) did not end the search
    assert ends[60] == "return to base" and np.hypot(*position) > 50.0  # the second, chosen away from home, did


def fly_until_the_search_ends(pilot, max_steps: int):
    """Fly the pilot's velocity commands exactly (1 s per step) from home; the decision that ended the search."""
    position = np.zeros(2)
    for _ in range(max_steps):
        decision = pilot.decide(position.copy())
        if decision.end is not None:
            return decision
        position = position + np.array(decision.velocity_ne) * 1.0
    raise AssertionError(f"the search did not end within {max_steps} steps")


def test_the_pilots_bingo_failsafe_ends_a_search_the_policy_would_not_end_in_time():
    """A policy that keeps searching past its last chance to fly home: the pilot ends the search ("bingo
    failsafe", the runner's RTL) once the way home would leave no more than BINGO_FAILSAFE_S of the endurance;
    without the failsafe the same flight runs dry."""
    from autonomy.search_pilot import BINGO_FAILSAFE_S, SearchPilot
    from missions.mission import Mission

    scenario = Scenario(area=AREA, datum_north_m=600.0, datum_east_m=50.0, datum_sigma_m=60.0, endurance_s=120.0,
                        targets=(Target("person", 900.0, 400.0, primary=True),), name="far-out")
    outcomes = {}
    for failsafe in (BINGO_FAILSAFE_S, None):
        pilot = SearchPilot(Mission(scenario=scenario), GoalScript([TRACK_OBJECT]), seed=7, bingo_failsafe_s=failsafe)
        decision = fly_until_the_search_ends(pilot, 200)
        outcomes[failsafe] = (decision.end, decision.step, float(pilot.state.bingo_margin_s[0]))
    end, step, margin = outcomes[BINGO_FAILSAFE_S]
    assert end == "bingo failsafe" and BINGO_FAILSAFE_S - 2.0 < margin <= BINGO_FAILSAFE_S
    assert outcomes[None][0] == "endurance exhausted" and outcomes[None][1] > step


def test_the_evaluations_flight_rule_reads_return_to_base_at_home_as_the_pilot_does():
    from missions.goals import RETURN_TO_BASE
    from policies.env.core import SarSearchConfig
    from policies.env.tasks import make_batch
    from policies.evaluation.episodes import run_episodes

    scenario = Scenario(area=AREA, datum_north_m=300.0, datum_east_m=50.0, datum_sigma_m=60.0, endurance_s=200.0,
                        targets=(Target("person", 330.0, 80.0, primary=True),), name="home-only")
    core = make_batch(SarSearchConfig(scenarios=(scenario,), goal_conditioned=True), [0, 1])
    record = run_episodes(core, lambda c: np.zeros((c.n, 4), dtype=np.float32),
                          lambda meta_obs: np.full(len(meta_obs), RETURN_TO_BASE), flight_rules=True)
    # never away from home: a hover over home, until the pilot's bingo failsafe ends the search (not a sortie
    # flown until its endurance is gone)
    assert record["length"].tolist() == [190, 190] and not record["ran_dry"].any()


def test_the_pilots_bingo_failsafe_also_ends_a_search_that_never_left_home():
    """ReturnToBase at every decision from home never ends the search by itself (it is a hover until the next
    decision); the failsafe ends it BINGO_FAILSAFE_S before the endurance is gone, not at 0 s."""
    from autonomy.search_pilot import BINGO_FAILSAFE_S, SearchPilot
    from missions.goals import RETURN_TO_BASE
    from missions.mission import Mission

    scenario = Scenario(area=AREA, datum_north_m=300.0, datum_east_m=50.0, datum_sigma_m=60.0, endurance_s=200.0,
                        targets=(Target("person", 330.0, 80.0, primary=True),), name="home-only")
    pilot = SearchPilot(Mission(scenario=scenario), GoalScript([RETURN_TO_BASE]), seed=7)
    decision = fly_until_the_search_ends(pilot, 300)
    assert decision.end == "bingo failsafe" and not pilot.state.left_home[0]
    assert decision.step == 200 - BINGO_FAILSAFE_S and float(pilot.state.bingo_margin_s[0]) <= BINGO_FAILSAFE_S


def test_the_evaluations_flight_rules_end_a_search_at_the_pilots_bingo_failsafe():
    """The same policy, flown out and kept searching: training's rules let the sortie run dry, the flight rules
    end it where the pilot's failsafe would (at most BINGO_FAILSAFE_S of the way home's margin left)."""
    from autonomy.search_pilot import BINGO_FAILSAFE_S
    from policies.env.core import SarSearchConfig
    from policies.env.tasks import make_batch
    from policies.evaluation.episodes import run_episodes

    scenario = Scenario(area=AREA, datum_north_m=600.0, datum_east_m=50.0, datum_sigma_m=60.0, endurance_s=120.0,
                        targets=(Target("person", 900.0, 400.0, primary=True),), name="far-out")
    north = np.array([1.0, 0.0, 1.0, 0.0], dtype=np.float32)  # straight north, sensor on
    lengths, ran_dry = {}, {}
    for rules in (False, True):
        core = make_batch(SarSearchConfig(scenarios=(scenario,), goal_conditioned=True), [0])
        record = run_episodes(core, lambda c: np.tile(north, (c.n, 1)),
                              lambda meta_obs: np.full(len(meta_obs), TRACK_OBJECT), flight_rules=rules)
        lengths[rules], ran_dry[rules] = int(record["length"][0]), bool(record["ran_dry"][0])
    assert ran_dry[False] and lengths[False] == 120
    assert not ran_dry[True] and lengths[True] < 120
    # ended on the step the margin fell to BINGO_FAILSAFE_S: 10 m/s north from home, so home is t * 10 m away
    assert abs(lengths[True] - (120.0 - BINGO_FAILSAFE_S) / 2.0) <= 2.0
