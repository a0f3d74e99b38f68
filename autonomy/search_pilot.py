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
from missions.action_frames import ActionFrame, movement_velocity
from missions.search_state_v1 import CONFIRMED, REJECTED, TARGET_SLOTS, BeliefSearchState
from missions.goals import GOAL_NAMES, NO_GOAL, RETURN_TO_BASE
from missions.mission import Mission
from missions.search import ScenarioBatch
from missions.shield import shield_velocity

END_REASONS = ("victim reached", "return to base", "returned home", "bingo failsafe", "endurance exhausted",
               "step limit", "entered a danger zone", "left the geofence", "victim reached by another drone")
"""Why a search ends (``Decision.end``); "victim reached" is the one success: the victim confirmed by a close look
and within the reach radius; in a fleet, the others' searches then end with "victim reached by another drone"."""
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
    def action_frame(self) -> ActionFrame:
        """How its movement is read."""

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
    ``bingo_failsafe_s``: see ``BINGO_FAILSAFE_S`` (None: off, the policy alone decides when to go home).

    ``state``: the search state to fly, one row per drone: by default the mission's single drone; a fleet's
    (``missions.fleet_search.FleetSearchState``) has one row per drone and one shared map, and is flown a round
    at a time (:meth:`decide_round`)."""

    def __init__(self, mission: Mission, policy: FlownPolicy, seed: int = 0,
                 bingo_failsafe_s: float | None = BINGO_FAILSAFE_S, state: BeliefSearchState | None = None):
        self.mission, self.policy = mission, policy
        self.bingo_failsafe_s = bingo_failsafe_s
        self.flight = mission.flight
        self.subgoal_interval = policy.subgoal_interval or self.flight.subgoal_interval
        # how the artifact's movement is read: north / east, or towards / right of the observation's target
        self.action_frame = policy.action_frame
        if state is None:
            # padded to the training environment's slots: the detection draws are keyed by slot
            scen = ScenarioBatch.from_scenarios([mission.scenario], [mission.geofence],
                                                num_targets=max(TARGET_SLOTS, len(mission.scenario.targets)))
            state = BeliefSearchState(scen, self.flight)
            state.reset(np.array([0]), np.array([seed], dtype=np.uint64))
        self.state = state
        policy.attach(state)
        n = state.n
        self.intensity = np.zeros(n)
        self.zoom = np.zeros(n)
        self.live = np.ones(n, dtype=bool)
        """Rows (drones) still searching: a row whose search ended takes no more decisions and looks no more."""
        self.goal_segments = np.zeros(n, dtype=np.int64)
        self.goals_reached = np.zeros(n, dtype=np.int64)
        self._segment_reached = np.zeros(n, dtype=bool)
        self._started = False

    @property
    def step(self) -> int:
        return int(self.state.steps[0])

    def decide(self, position_ne: np.ndarray) -> Decision:
        """One decision at the drone's position (2,); the first call starts the search there."""
        decision = self.decide_round(np.asarray(position_ne, dtype=np.float64).reshape(1, 2), np.ones(1, dtype=bool))
        return decision[0]

    def decide_round(self, positions_ne: np.ndarray, searching: np.ndarray) -> list[Decision | None]:
        """One decision step of every row at its drone's position (N, 2); the first call starts the search there.
        ``searching`` (N,): the drones that search this step; the others (blind, or not searching yet) move on in
        time with their camera off and get None, as do rows whose search has ended."""
        state, n = self.state, self.state.n
        position = np.asarray(positions_ne, dtype=np.float64).reshape(n, 2)
        acting = self.live & np.asarray(searching, dtype=bool)
        ends: list[str | None] = [None] * n
        if not self._started:  # the search starts where the drones are: no step flown yet
            self._started = True
            state.position[:] = position
        else:
            out = state.advance(position, np.where(acting, self.intensity, 0.0), self.zoom, self.flight.step_period_s)
            self._segment_reached |= out.goal_reached
            ends = self._end_reasons(out)
        ends = [end if self.live[i] else None for i, end in enumerate(ends)]
        if n > 1 and "victim reached" in ends:  # the find ends the search for the whole fleet
            ends = [end or ("victim reached by another drone" if self.live[i] else None) for i, end in enumerate(ends)]
        deciding = acting & np.array([end is None for end in ends])
        state.searching[:] = deciding  # what the fleet's planner splits the water among
        new_goal = np.zeros(n, dtype=bool)
        if self.policy.hierarchical:
            due = deciding & state.goal_due(self.subgoal_interval)
            if due.any():
                rows = np.flatnonzero(due)
                self._close_segments(due)
                meta = observe_search(state, True)[rows, :LAYOUT_V4.meta_dim]
                goals = np.full(n, NO_GOAL)
                goals[rows] = self.policy.select_goal(meta[0]) if n == 1 else self.policy.select_goal(meta)
                state.set_goals(goals, mask=due)
                new_goal = due
                for row in rows:
                    if goals[row] == RETURN_TO_BASE and state.left_home[row]:
                        # Home, once the drone has been away (as the environment's "returned"): the runner's RTL
                        # flies it. Chosen before it has left, ReturnToBase holds over home until the next decision.
                        ends[row] = "return to base"
        obs = observe_search(state, self.policy.hierarchical)
        action = (self.policy.act(obs[0])[None] if n == 1 else self.policy.act(obs)).astype(np.float64)
        ended = np.array([end is not None for end in ends])
        self._close_segments(ended)
        finite = np.all(np.isfinite(action), axis=1)
        update = finite & acting
        self.intensity[update] = np.clip(action[update, 2], 0.0, 1.0)
        self.zoom[update] = np.clip(action[update, 3], 0.0, 1.0)
        # as the training environment read it (its action_frame), then its safety filter: danger zones, geofence
        movement = np.where(finite[:, None], np.clip(np.nan_to_num(action[:, :2]), -1.0, 1.0), 0.0)
        target_ne = state.target_position(self.policy.hierarchical)
        movement = movement_velocity(movement, state.position, target_ne, self.action_frame,
                                     self.flight.max_speed_mps, self.flight.step_period_s)
        scen = state.scen
        movement = shield_velocity(state.position, movement, scen.obstacles, scen.obstacle_valid, scen.fence)
        movement[~finite] = np.nan
        decisions: list[Decision | None] = [None] * n
        for row in np.flatnonzero(acting):
            target = float(state.altitude_target[row])
            decisions[row] = Decision(
                int(state.steps[row]), (float(movement[row, 0]), float(movement[row, 1])),
                float(self.intensity[row]), float(self.zoom[row]), int(state.goal[row]),
                tuple(state.goal_point[row].tolist()), bool(new_goal[row]), ends[row],
                tuple(float(a) for a in action[row]),
                None if target == float(state.search_altitude_m[row]) else target)
        self.live &= ~ended
        return decisions

    def _end_reasons(self, out) -> list[str | None]:
        state = self.state
        # Wherever the drone is, home included: a policy that never leaves home must not hover there until the
        # sortie's endurance is gone either.
        past_bingo = (np.zeros(state.n, dtype=bool) if self.bingo_failsafe_s is None
                      else state.bingo_margin_s <= self.bingo_failsafe_s)
        reasons: list[str | None] = []
        for row in range(state.n):
            reason = None
            for ended, why in ((out.success, "victim reached"), (out.collision, "entered a danger zone"),
                               (out.out_of_bounds, "left the geofence"), (out.returned, "returned home"),
                               (out.ran_dry, "endurance exhausted")):
                if ended[row]:
                    reason = why
                    break
            if reason is None and int(state.steps[row]) >= self.flight.max_steps:
                reason = "step limit"
            if reason is None and past_bingo[row]:
                reason = "bingo failsafe"
            reasons.append(reason)
        return reasons

    def _close_segments(self, rows: np.ndarray) -> None:
        closing = rows & (self.state.goal != NO_GOAL)
        self.goal_segments += closing
        self.goals_reached += closing & self._segment_reached
        self._segment_reached[rows] = False

    def summary(self, row: int = 0) -> dict:
        """The search part of the mission report (of drone ``row`` of a fleet)."""
        state = self.state
        first = int(state.first_detection_step[row])
        segments = int(self.goal_segments[row])
        return {
            "steps": int(state.steps[row]),
            "victim_detected": bool(state.has_detection[row]),
            "victim_confirmed": bool(state.status[row, state.scen.primary_index[row]] == CONFIRMED),
            "candidates_rejected": int((state.status[row] == REJECTED).sum()),
            "energy_left": float(state.energy_left[row]),
            "first_detection_step": first if first >= 0 else None,
            "time_to_detection_s": first * self.flight.step_period_s if first >= 0 else None,
            "coverage_ratio": float(state.coverage_ratio[row]),
            "subgoal_reachability": (int(self.goals_reached[row]) / segments) if segments else None,
            "goal_names": list(GOAL_NAMES),
        }


class DecisionSource(Protocol):
    """Where the runner's SEARCH state gets its decisions (``autonomy.search_loop``): its own pilot
    (:class:`DecisionWorker`) or its seat in a fleet's decision rounds (``autonomy.fleet_runner.FleetSeat``)."""

    def begin(self, now_s: float, period_s: float) -> None:
        """The runner is ready to search, one decision every ``period_s`` from now."""

    def started(self) -> bool:
        """Whether decisions may start (a fleet waits for all its drones to be ready)."""

    def due(self, now_s: float) -> bool:
        """Whether the runner should hand in its position for a decision now."""

    def submit(self, position_ne: np.ndarray, now_s: float) -> None:
        """The filtered position (2,) for the decision that is due."""

    def poll(self, now_s: float) -> Decision | None:
        """The finished decision, once (None while computing or idle)."""


class DecisionWorker:
    """Runs ``pilot.decide`` off the control loop (a :class:`DecisionSource`): ``threaded`` in real time,
    simulated latency in lockstep."""

    def __init__(self, pilot: SearchPilot, threaded: bool, simulated_compute_s: float = 0.0):
        self.pilot, self.threaded = pilot, threaded
        self.compute_time_s = simulated_compute_s
        self._pending: tuple[float, Decision] | None = None
        self._thread: threading.Thread | None = None
        self._result: Decision | None = None
        self._next_s = 0.0
        self._period_s = 1.0

    @property
    def busy(self) -> bool:
        return self._pending is not None or (self._thread is not None and self._thread.is_alive())

    def begin(self, now_s: float, period_s: float) -> None:
        self._next_s, self._period_s = now_s, period_s

    def started(self) -> bool:
        return True

    def due(self, now_s: float) -> bool:
        return now_s + 1e-9 >= self._next_s and not self.busy

    def submit(self, position_ne: np.ndarray, now_s: float) -> None:
        # One period after the scheduled decision; a decision that came late (slow policy) skips the missed periods
        # instead of a burst of back-to-back decisions, each counted as a full step.
        self._next_s += self._period_s
        if self._next_s <= now_s:
            self._next_s = now_s + self._period_s
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
