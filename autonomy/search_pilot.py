"""The search brain of the mission runner: one policy decision per step, from the filtered pose.

Each decision step (``FlightSettings.step_period_s``) the runner hands :meth:`SearchPilot.decide` the drone's
filtered (north, east) in the mission frame. The pilot then does exactly what the training environment
(SarSearch-v1) does after its dynamics step, with the same ``missions.search_state_v1.BeliefSearchState`` (belief,
candidates, confirmation rule, endurance) and the same observation builder:

1. advance the search state to that position with the sensor settings of the previous decision: the camera's
   modelled altitude, drift, the belief, sightings by the simulated camera (the mission's objects and the detection
   model, with draws keyed by the mission seed), close looks and their identifications, end conditions;
2. every K steps (a hierarchical policy) choose a goal from the meta observation and ground it to a point;
3. act on the observation: movement in [-1, 1] scaled to the mission's speed limit (north/east, or towards and to
   the right of the observation's target, slowing on the last step with "arrive", when the artifact was trained so:
   its ``action_frame``, ``missions.action_frames.movement_velocity``), search
   intensity and camera zoom in [0, 1], the velocity passed through the environment's safety shield (danger zones,
   geofence: ``missions.shield``); during a close look, :attr:`Decision.altitude_m` asks the runner for the
   close-look altitude (the search state's ``altitude_target``), which it flies with vertical velocity.

The camera is simulated in every mode, also against a real autopilot: a real payload would feed its
detections here instead (not built; see docs/runner.md). The search state models the camera's altitude itself
(descent and climb at the rates of ``missions.search_state_v1``), so the runner's altitude controller need not match
it to the metre.

:class:`DecisionWorker` runs ``decide`` off the runner's control loop, which must keep streaming setpoints whatever
the policy does: in real time in a thread (a slow policy delays decisions, never setpoints), in lockstep
synchronously with its answer released after ``compute_time_s`` of simulated time (0 unless a test makes a policy
slow), so that replays stay deterministic.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from autonomy.observation import LAYOUT_V4, observe_search
from missions.action_frames import movement_velocity
from missions.search_state_v1 import CONFIRMED, REJECTED, TARGET_SLOTS, BeliefSearchState
from missions.goals import GOAL_NAMES, NO_GOAL, RETURN_TO_BASE
from missions.mission import Mission
from missions.search import ScenarioBatch
from missions.shield import shield_velocity

END_REASONS = ("victim reached", "return to base", "returned home", "bingo failsafe", "endurance exhausted",
               "step limit", "entered a danger zone", "left the geofence")
"""Why a search ends (``Decision.end``); "victim reached" is the one success: the victim confirmed by a close look
and within the reach radius."""
BINGO_FAILSAFE_S = 10.0
"""The pilot ends the search ("bingo failsafe"; the runner's RTL then flies home) once flying home at full speed
would leave no more than this of the sortie's endurance, whatever the policy chose. The meta-controller had its
bingo call at ``missions.search_state_v1.BINGO_RESERVE_S`` (20 s); a learned policy is not trusted with the last of
the fuel, as PX4's and ArduPilot's battery failsafes do not trust a companion computer with the battery."""


class FlownPolicy(Protocol):
    """What the pilot needs of a policy: :class:`autonomy.policy.Policy` (a loaded artifact) or a scripted searcher
    (:class:`autonomy.pilots.ScriptedPilot`)."""

    @property
    def hierarchical(self) -> bool:
        """Whether a meta-controller chooses goals (``select_goal``)."""

    @property
    def subgoal_interval(self) -> int | None:
        """K: steps between goal decisions (None: the mission's)."""

    @property
    def action_frame(self) -> str:
        """How its movement is read (``missions.action_frames.ACTION_FRAMES``)."""

    def select_goal(self, meta_obs: np.ndarray) -> np.ndarray:
        """The goal index for a meta observation."""

    def act(self, obs: np.ndarray) -> np.ndarray:
        """The action (4,) for an observation."""

    def attach(self, state: BeliefSearchState) -> None:
        """Called once, before the first decision, with the search state the pilot keeps: a scripted searcher
        reads the crew's map and candidates from it; an artifact needs only the observation."""

    def describe(self) -> dict:
        """What the mission report says of the pilot: its name ("pilot") and what identifies it exactly."""


@dataclass(frozen=True)
class Decision:
    """One step's outcome: what to fly, and whether the search is over (and why)."""

    step: int
    velocity_ne: tuple[float, float]
    """Horizontal velocity command (m/s), north and east."""
    intensity: float
    zoom: float
    goal: int
    """Current goal index (NO_GOAL for a flat policy)."""
    goal_point: tuple[float, float]
    new_goal: bool
    """Whether the meta-controller decided this step."""
    end: str | None = None
    """None while searching; else one of END_REASONS: "victim reached" (the one success), "return to base" (the
    meta-controller chose ReturnToBase after the drone had left home), "returned home" (a flat policy came back
    over home), "bingo failsafe" (the policy kept searching past its last chance to fly home: ``BINGO_FAILSAFE_S``),
    "endurance exhausted" (the sortie's endurance is used up), "step limit", "entered a danger zone" or "left the
    geofence"."""
    action: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    """The policy's raw action (NaN if it returned one: the runner's guard decides)."""
    altitude_m: float | None = None
    """Altitude above home this step asks for: the close-look altitude while the camera looks closely at a
    candidate; None = the mission's ``FlightSettings.altitude_m``."""


class SearchPilot:
    """Turns filtered positions into policy decisions for one mission; see the module docstring.
    ``bingo_failsafe_s``: see ``BINGO_FAILSAFE_S`` (None: off, the policy alone decides when to go home)."""

    def __init__(self, mission: Mission, policy: FlownPolicy, seed: int = 0,
                 bingo_failsafe_s: float | None = BINGO_FAILSAFE_S):
        self.mission, self.policy = mission, policy
        self.bingo_failsafe_s = bingo_failsafe_s
        self.flight = mission.flight
        self.subgoal_interval = policy.subgoal_interval or self.flight.subgoal_interval
        # how the artifact's movement is read: north / east, or towards / right of the observation's target
        self.action_frame = policy.action_frame
        # padded to the training environment's slots: the detection draws are keyed by slot
        scen = ScenarioBatch.from_scenarios([mission.scenario], [mission.geofence],
                                            num_targets=max(TARGET_SLOTS, len(mission.scenario.targets)))
        self.state = BeliefSearchState(scen, self.flight)
        self.state.reset(np.array([0]), np.array([seed], dtype=np.uint64))
        policy.attach(self.state)
        self.intensity = np.zeros(1)
        self.zoom = np.zeros(1)
        self.goal_segments = 0
        self.goals_reached = 0
        self._segment_reached = False
        self._started = False

    @property
    def step(self) -> int:
        return int(self.state.steps[0])

    def decide(self, position_ne: np.ndarray) -> Decision:
        """One decision at the drone's position (2,); the first call starts the search there."""
        state = self.state
        position = np.asarray(position_ne, dtype=np.float64).reshape(1, 2)
        end = None
        if not self._started:  # the search starts where the drone is: no step flown yet
            self._started = True
            state.position[:] = position
        else:
            out = state.advance(position, self.intensity, self.zoom, self.flight.step_period_s)
            self._segment_reached |= bool(out.goal_reached[0])
            end = self._end_reason(out)
            if end is None and self._past_bingo():
                end = "bingo failsafe"
        new_goal = False
        if end is None and self.policy.hierarchical and state.goal_due(self.subgoal_interval)[0]:
            self._close_segment()
            goal = int(self.policy.select_goal(observe_search(state, True)[0, :LAYOUT_V4.meta_dim]))
            state.set_goals(np.array([goal]))
            new_goal = True
            if goal == RETURN_TO_BASE and state.left_home[0]:
                # Home, once the drone has been away (as the environment's "returned"): the runner's RTL flies it.
                # Chosen before it has left, ReturnToBase holds over home until the next decision, as in training.
                end = "return to base"
        obs = observe_search(state, self.policy.hierarchical)
        action = self.policy.act(obs[0]).astype(np.float64)
        if end is not None:
            self._close_segment()
        finite = bool(np.all(np.isfinite(action)))
        if finite:
            self.intensity[0], self.zoom[0] = np.clip(action[2:4], 0.0, 1.0)
        movement = np.clip(action[:2], -1.0, 1.0) if finite else np.array([np.nan] * 2)
        if finite:  # as the training environment read it (its action_frame)
            target_ne = state.target_position(self.policy.hierarchical)
            movement = movement_velocity(movement[None], state.position, target_ne, self.action_frame,
                                         self.flight.max_speed_mps, self.flight.step_period_s)[0]
        else:
            movement = movement * self.flight.max_speed_mps
        if finite:  # the environment's safety filter: danger zones and geofence (missions.shield)
            scen = state.scen
            movement = shield_velocity(state.position, movement[None], scen.obstacles, scen.obstacle_valid,
                                       scen.fence)[0]
        target = float(state.altitude_target[0])
        return Decision(self.step, (float(movement[0]), float(movement[1])), float(self.intensity[0]),
                        float(self.zoom[0]), int(state.goal[0]), tuple(state.goal_point[0].tolist()), new_goal,
                        end, tuple(float(a) for a in action),
                        None if target == self.flight.altitude_m else target)

    def _past_bingo(self) -> bool:
        state = self.state
        # Wherever the drone is, home included: a policy that never leaves home must not hover there until the
        # sortie's endurance is gone either.
        return self.bingo_failsafe_s is not None and float(state.bingo_margin_s[0]) <= self.bingo_failsafe_s

    def _end_reason(self, out) -> str | None:
        for ended, reason in ((out.success, "victim reached"), (out.collision, "entered a danger zone"),
                              (out.out_of_bounds, "left the geofence"), (out.returned, "returned home"),
                              (out.ran_dry, "endurance exhausted")):
            if ended[0]:
                return reason
        if self.step >= self.flight.max_steps:
            return "step limit"
        return None

    def _close_segment(self) -> None:
        if self.state.goal[0] != NO_GOAL:
            self.goal_segments += 1
            self.goals_reached += self._segment_reached
        self._segment_reached = False

    def summary(self) -> dict:
        """The search part of the mission report."""
        state = self.state
        first = int(state.first_detection_step[0])
        return {
            "steps": self.step,
            "victim_detected": bool(state.has_detection[0]),
            "victim_confirmed": bool(state.status[0, state.scen.primary_index[0]] == CONFIRMED),
            "candidates_rejected": int((state.status[0] == REJECTED).sum()),
            "energy_left": float(state.energy_left[0]),
            "first_detection_step": first if first >= 0 else None,
            "time_to_detection_s": first * self.flight.step_period_s if first >= 0 else None,
            "coverage_ratio": float(state.coverage_ratio[0]),
            "subgoal_reachability": (self.goals_reached / self.goal_segments) if self.goal_segments else None,
            "goal_names": list(GOAL_NAMES),
        }


class DecisionWorker:
    """Runs ``pilot.decide`` off the control loop; ``threaded`` in real time, simulated latency in lockstep."""

    def __init__(self, pilot: SearchPilot, threaded: bool, simulated_compute_s: float = 0.0):
        self.pilot, self.threaded = pilot, threaded
        self.compute_time_s = simulated_compute_s
        self._pending: tuple[float, Decision] | None = None
        self._thread: threading.Thread | None = None
        self._result: Decision | None = None

    @property
    def busy(self) -> bool:
        return self._pending is not None or (self._thread is not None and self._thread.is_alive())

    def submit(self, position_ne: np.ndarray, now_s: float) -> None:
        if self.threaded:
            def work() -> None:
                self._result = self.pilot.decide(position_ne)
            self._thread = threading.Thread(target=work, name="policy", daemon=True)
            self._thread.start()
        else:
            self._pending = (now_s + self.compute_time_s, self.pilot.decide(position_ne))

    def poll(self, now_s: float) -> Decision | None:
        """The finished decision, once (None while computing or idle)."""
        if self.threaded:
            if self._thread is not None and not self._thread.is_alive():
                self._thread, result, self._result = None, self._result, None
                return result
            return None
        if self._pending is not None and now_s + 1e-9 >= self._pending[0]:
            decision, self._pending = self._pending[1], None
            return decision
        return None
