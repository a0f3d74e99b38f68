"""The state of N searches of SarSearch-v1, advanced one decision step at a time: what training and flight share.

The training environment (``policies.env.task_v1``) and the mission runner's pilot (``autonomy.search_pilot``)
both keep a :class:`BeliefSearchState`; they differ only in where the drone's position comes from. What the
search logic knows is what a crew knows: the area, the charted danger zones, the datum and its forecast drift,
the conditions, its own position and its own sightings. Which object is the victim it learns only from a close
look. One step, :meth:`BeliefSearchState.advance`, given the position the drone reached and its sensor settings:

1. the camera's altitude moves towards the altitude the last step asked for (a close look descends to
   ``CLOSE_LOOK_ALTITUDE_M`` at ``DESCENT_MPS``, the search altitude is regained at ``CLIMB_MPS``);
2. objects drift with the true current and leeway; the belief (``missions.belief``) with the forecast;
3. the camera may detect objects (draws keyed by (episode seed, step), as in SarSearch-v0). A sighting of the
   reported category (the victim's: person, swimmer or life jacket) becomes or updates a *candidate*; other
   categories are recognised as what they are and only fill the observation's detection binaries;
4. the look lowers the belief where the footprint was, by the detection probability of the reported category;
5. a close look identifies a candidate: the object in the footprint, the drone at most ``CLOSE_LOOK_SPEED_MPS``
   fast, with probability ``p_detect`` computed at ``IDENTIFY_SIZE_FACTOR`` times the object's size (Johnson's
   criteria: identifying an object takes about 6.4 times the resolution detecting it does). The victim becomes
   *confirmed*, a decoy *rejected*. Hovering over a candidate's estimate for ``LOST_AFTER_S`` without seeing it
   marks it *lost* until it is sighted again;
6. end conditions: the drone within the reach radius of the victim once confirmed (success), a danger zone
   entered, the geofence left, the endurance used up (``ran_dry``), or back over home (hovering, after having left
   it: ``returned``);
7. a goal whose point was reached is grounded again (``missions.goals.ground_goals_v1``);
8. the decision events: a step that sighted a new candidate, or after which the drone can only just come home
   (the bingo call: ``BINGO_RESERVE_S`` to spare), asks the meta-controller for a goal before the next step
   (:meth:`BeliefSearchState.goal_due`), besides the decision every K steps.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from missions import belief as belief_logic
from missions import goals as goal_logic
from missions import search
from missions.goals import NO_GOAL, TRACK_OBJECT
from missions.mission import FlightSettings
from missions.scenario import CATEGORIES
from missions.search_state_v0 import checked_goals, keyed_uniforms

TARGET_SLOTS = 16
"""Target slots of a scenario in SarSearch-v1 (the environment's and the pilot's): the detection draws are keyed by
slot, so both must pad to the same number for the same path to see the same draws."""
NONE, UNRESOLVED, REJECTED, CONFIRMED, LOST = range(5)
"""Candidate states of an object (per target slot): never sighted as a candidate, sighted and not yet identified,
identified as a decoy, identified as the victim, hovered over without being seen (sighted again: unresolved)."""
CLOSE_LOOK_ALTITUDE_M = 20.0
"""Altitude of a close look (m above home), or the search altitude when that is lower."""
CLOSE_LOOK_SPEED_MPS = 3.0
"""Fastest ground speed at which the camera can identify an object (it has to hold it in view), and at which a
drone over home counts as landing there."""
IDENTIFY_SIZE_FACTOR = 1.0 / 6.4
"""Identification is detection at this share of the object's size: 6.4 against 1 resolution cycles (Johnson)."""
DESCENT_MPS = 1.5
"""Descent rate of a close look (the SITL multirotor's limit, ``MultirotorParams.max_speed_down_mps``)."""
CLIMB_MPS = 2.0
"""Climb rate back to the search altitude (the runner's vertical setpoint clamp, ``StreamConfig``)."""
LOST_AFTER_S = 20.0
"""Seconds of close look at a candidate's estimated position without sighting it before it counts as lost."""
REACHABLE_MARGIN_M = 10.0
"""A candidate is flown to only while its estimate lies this far inside the area and outside every danger zone."""
LEFT_HOME_M = 50.0
"""The search has left home once the drone was this far from it; only then does coming back end it."""
RETURN_RESERVE = 0.1
"""Share of the endurance a crew keeps for landing: a return home with at least this much left pays
(``policies.env.task_v1``)."""
BINGO_RESERVE_S = 20.0
"""The bingo call, a decision event, comes on the step after which the way home at full speed would leave no more
than this (s): the last decision that can still bring the drone home (the scripted searchers turn home with the
same reserve, ``missions.searchers.TUNED``). Later, the next decision may come too late."""
IDENTIFY_STREAM = np.uint64(0x1D5EED)
"""Mixed into the episode seed for the identification draws: a stream of their own beside the detections'."""


@dataclass
class BeliefStepOutcome:
    """What one :meth:`BeliefSearchState.advance` found, per search (N,) arrays; views valid until the next step."""

    success: np.ndarray
    collision: np.ndarray
    out_of_bounds: np.ndarray
    ran_dry: np.ndarray
    returned: np.ndarray
    distance_to_victim_m: np.ndarray
    goal_reached: np.ndarray
    goal_moved_on: np.ndarray
    step_goal_point: np.ndarray
    """(N, 2) the goal point this step flew towards (before any re-grounding)."""
    belief_removed: np.ndarray
    """The belief this step's look removed: the chance, under the crew's model, that it detected the victim."""
    identify_chance: np.ndarray
    """The chance, under the crew's model, that this step's look identified an unresolved candidate: the
    identification probability at the candidates' estimates (not where they really are), 0 when too fast."""


class BeliefSearchState:
    """N searches of SarSearch-v1; see the module docstring. ``scen`` is a padded ``search.ScenarioBatch``;
    ``map_cells`` the belief map's cells per side (``missions.belief.map_cells`` of the largest area these searches
    will fly; by default of ``scen``'s areas): a batch whose scenarios are drawn later says it."""

    def __init__(self, scen: search.ScenarioBatch, flight: FlightSettings, map_cells: int | None = None):
        self.scen, self.flight = scen, flight
        self.n = n = len(scen.datum)
        self.max_targets = t = scen.targets.shape[1]
        g = belief_logic.map_cells(scen.area) if map_cells is None else map_cells
        self.position, self.targets = np.zeros((n, 2)), np.zeros((n, t, 2))
        self.altitude, self.altitude_target, self.speed_mps = np.zeros(n), np.zeros(n), np.zeros(n)
        self.search_altitude_m = np.full(n, float(flight.altitude_m))
        """(N,) each search's altitude above home (m): the flight's, or a fleet drone's own layer."""
        self.searching = np.ones(n, dtype=bool)
        """(N,) whose drone searches now: a fleet's planner (``missions.searchers.fleet``) leaves the others out."""
        self.time_s, self.steps = np.zeros(n), np.zeros(n, dtype=np.int64)
        self.episode_seed = np.zeros(n, dtype=np.uint64)
        self.belief, self.coverage = np.zeros((n, g, g)), np.zeros((n, g, g))
        self.belief_offset, self.blurred_s, self.prior_peak = np.zeros((n, 2)), np.zeros(n), np.ones(n)
        self.detections = np.zeros((n, len(CATEGORIES)), dtype=bool)
        self.status = np.zeros((n, t), dtype=np.int64)
        self.sighting = np.zeros((n, t, 2))
        """(N, T, 2) where each candidate was last sighted; :meth:`candidate_estimates` drifts it to now."""
        self.sighted_s, self.unseen_look_s, self.plausibility = np.zeros((n, t)), np.zeros((n, t)), np.zeros((n, t))
        self.left_home = np.zeros(n, dtype=bool)
        self.has_detection = np.zeros(n, dtype=bool)  # the victim sighted (evaluation only: the logic never reads it)
        self.first_detection_step = np.full(n, -1, dtype=np.int64)
        self.goal, self.goal_point = np.full(n, NO_GOAL, dtype=np.int64), np.zeros((n, 2))
        self.goal_steps = np.zeros(n, dtype=np.int64)
        """Steps flown under the current goal (0 at a search's start and at each decision)."""
        self.decision_event = np.zeros(n, dtype=bool)
        """The last step sighted a new candidate or made the bingo call (module docstring, step 8); cleared by a
        decision."""
        self._flat_target = np.zeros((n, 2))
        self._flat_target_due = True  # computed when a flat policy asks for it (HRL-SAC never does)
        self._estimates, self._kind = np.zeros((n, t, 2)), np.zeros((n, t), dtype=np.int64)
        self._identify_chance = np.zeros(n)
        self._new_candidate = np.zeros(n, dtype=bool)
        self._arange = np.arange(n)

    # ------------------------------------------------------------------ episodes and goals
    def reset(self, indices: np.ndarray, episode_seeds: np.ndarray) -> None:
        """Start the searches ``indices`` (whose ``scen`` rows are already set) from their start points."""
        scen = self.scen
        self.targets[indices] = scen.targets[indices]
        self.position[indices] = scen.start[indices]
        self.altitude[indices] = self.altitude_target[indices] = self.search_altitude_m[indices]
        self.speed_mps[indices] = self.time_s[indices] = self.blurred_s[indices] = 0.0
        self.steps[indices] = 0
        self.episode_seed[indices] = episode_seeds
        self.belief[indices] = belief_logic.prior(scen.area[indices], scen.datum[indices], scen.datum_sigma[indices],
                                                  self.belief.shape[1])
        self.prior_peak[indices] = np.maximum(self.belief[indices].max(axis=(1, 2)), 1e-12)
        self.coverage[indices] = self.belief_offset[indices] = 0.0
        self.detections[indices] = False
        self.status[indices] = NONE
        self.sighting[indices] = self.sighted_s[indices] = self.unseen_look_s[indices] = 0.0
        self.plausibility[indices] = 0.0
        self.left_home[indices] = self.has_detection[indices] = False
        self.first_detection_step[indices] = -1
        self.goal[indices] = NO_GOAL
        self.goal_point[indices] = scen.datum[indices]
        self.goal_steps[indices] = 0
        self.decision_event[indices] = False
        self._refresh_candidates()

    def set_goals(self, goals: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """Give searches a meta-controller goal (index into GOAL_NAMES) and ground it now; returns the mask."""
        goals, mask = checked_goals(goals, mask, self.n)
        self.goal[mask] = goals[mask]
        self.goal_point[mask] = self._points(self.goal[mask], mask)
        self.goal_steps[mask] = 0
        self.decision_event[mask] = False
        return mask

    def goal_due(self, subgoal_interval: int) -> np.ndarray:
        """(N,) whether each search's meta-controller chooses a goal before the next step: at the start, K steps
        after the last decision, and at once after a decision event (``missions.goals.goal_due``)."""
        return goal_logic.goal_due(self.goal_steps, subgoal_interval, self.decision_event)

    @property
    def bingo_margin_s(self) -> np.ndarray:
        """(N,) seconds of endurance that would be left after flying home now at full speed (inf when unlimited)."""
        home_s = np.hypot(*(self.position - self.scen.start).T) / self.flight.max_speed_mps
        return self.scen.endurance_s - self.time_s - home_s

    def _points(self, goal: np.ndarray, rows: np.ndarray) -> np.ndarray:
        scen = self.scen
        estimates, kind = self._estimates[rows], self._kind[rows]
        return goal_logic.ground_goals_v1(goal, self.position[rows], scen.area[rows], self.coverage[rows],
                                          self.belief[rows], self.belief_offset[rows], estimates, kind,
                                          scen.datum_at(self.time_s)[rows], scen.start[rows], scen.obstacles[rows],
                                          scen.obstacle_valid[rows])

    def target_position(self, goal_conditioned: bool) -> np.ndarray:
        """What the observation calls the target: the goal's point (HRL-SAC), or for a flat policy the point
        TrackObject would be grounded to (a candidate to look at or reach, else the most probable place)."""
        if goal_conditioned:
            return self.goal_point
        if self._flat_target_due:
            self._flat_target = self._points(np.full(self.n, TRACK_OBJECT), np.ones(self.n, dtype=bool))
            self._flat_target_due = False
        return self._flat_target

    # ------------------------------------------------------------------ candidates
    def candidate_estimates(self) -> np.ndarray:
        """(N, T, 2) where each candidate is now by the forecast: its last sighting drifted with the forecast."""
        return self._estimates

    def candidate_kind(self) -> np.ndarray:
        """(N, T) 0 = not to be flown to, 1 = unresolved and reachable, 2 = the confirmed victim."""
        return self._kind

    def _refresh_candidates(self) -> None:
        """The candidates' estimates and kinds as they stand (kept until the state changes: read many times)."""
        elapsed = (self.time_s[:, None] - self.sighted_s)[:, :, None]
        self._estimates = estimates = self.sighting + self.scen.forecast_drift[:, None, :] * elapsed
        self._flat_target_due = True
        scen = self.scen
        inside = ((estimates[..., 0] >= scen.area[:, 0:1] + REACHABLE_MARGIN_M)
                  & (estimates[..., 0] <= scen.area[:, 1:2] - REACHABLE_MARGIN_M)
                  & (estimates[..., 1] >= scen.area[:, 2:3] + REACHABLE_MARGIN_M)
                  & (estimates[..., 1] <= scen.area[:, 3:4] - REACHABLE_MARGIN_M))
        zones = scen.obstacles
        gap = (np.hypot(estimates[:, :, None, 0] - zones[:, None, :, 0],
                        estimates[:, :, None, 1] - zones[:, None, :, 1]) - zones[:, None, :, 2])
        clear = np.where(scen.obstacle_valid[:, None, :], gap >= REACHABLE_MARGIN_M, True).all(axis=2)
        kind = np.where(self.status == UNRESOLVED, 1, 0)
        kind[self.status == CONFIRMED] = 2
        self._kind = np.where(inside & clear | (kind == 2), kind, 0)

    # ------------------------------------------------------------------ one step
    def advance(self, position: np.ndarray, intensity: np.ndarray, zoom: np.ndarray,
                dt_s: float) -> BeliefStepOutcome:
        """One decision step: the drones flew to ``position`` (N, 2) with these sensor settings (N,)."""
        flight, scen, rows = self.flight, self.scen, self._arange
        margin_before = self.bingo_margin_s
        self.speed_mps = np.hypot(*(position - self.position).T) / dt_s
        self.position[:] = position
        self.time_s += dt_s
        self.steps += 1
        self.goal_steps += 1
        self.altitude += np.clip(self.altitude_target - self.altitude, -DESCENT_MPS * dt_s, CLIMB_MPS * dt_s)
        search.drift_targets(self.targets, scen.drift_velocity, dt_s)
        self.drift_map(dt_s)

        reported = scen.target_category[rows, scen.primary_index]
        probability = scen.detection_probability(position, self.targets, self.altitude, zoom, intensity)
        detected = keyed_uniforms(self.episode_seed, self.steps, self.max_targets) < probability
        self.detections = search.detected_categories(detected, scen.target_category)
        self._update_candidates(detected & (scen.target_category == reported[:, None]), intensity, zoom, dt_s)
        victim_seen = detected[rows, scen.primary_index]
        first = victim_seen & ~self.has_detection
        self.first_detection_step[first] = self.steps[first]
        self.has_detection |= victim_seen
        removed = self._look(position, zoom, intensity, search.OBJECT_SIZE_M[reported],
                             scen.detection_factor[rows, scen.primary_index])

        distance = search.distance_to_primary(position, self.targets, scen.primary_index)
        success = (self.status[rows, scen.primary_index] == CONFIRMED) & (distance <= flight.reach_radius_m)
        collision = search.inside_obstacle(position, scen.obstacles, scen.obstacle_valid) & ~success
        out_of_bounds = search.outside_fence(position, scen.fence) & ~success
        from_home = np.hypot(*(position - scen.start).T)
        self.left_home |= from_home > LEFT_HOME_M
        ending = success | collision | out_of_bounds
        returned = (self.left_home & (from_home <= flight.reach_radius_m) & (self.speed_mps <= CLOSE_LOOK_SPEED_MPS)
                    & ~ending)
        ran_dry = (self.time_s >= scen.endurance_s) & ~ending & ~returned

        self._refresh_candidates()
        step_goal_point = self.goal_point.copy()
        reached = (self.goal != NO_GOAL) & (np.hypot(*(position - step_goal_point).T) <= flight.reach_radius_m)
        if reached.any():
            self.goal_point[reached] = self._points(self.goal[reached], reached)
        moved_on = reached & (np.hypot(*(self.goal_point - step_goal_point).T) > flight.reach_radius_m)
        self.altitude_target[:] = np.where(self.close_look(), np.minimum(self.search_altitude_m, CLOSE_LOOK_ALTITUDE_M),
                                           self.search_altitude_m)
        bingo = (margin_before > BINGO_RESERVE_S) & (self.bingo_margin_s <= BINGO_RESERVE_S)
        self.decision_event |= self._new_candidate | bingo
        return BeliefStepOutcome(success, collision, out_of_bounds, ran_dry, returned, distance, reached, moved_on,
                                 step_goal_point, removed, self._identify_chance)

    def _look(self, position: np.ndarray, zoom: np.ndarray, intensity: np.ndarray, size_m: np.ndarray,
              factor: np.ndarray) -> np.ndarray:
        """Each search's look lowers its own map (``missions.belief.look``); a fleet's searches share one
        (``missions.fleet_search``). Returns the belief each look removed (N,)."""
        return belief_logic.look(self.belief, self.coverage, self.scen.area, self.belief_offset, position,
                                 self.altitude, zoom, intensity, size_m, factor)

    def _update_candidates(self, sighted: np.ndarray, intensity: np.ndarray, zoom: np.ndarray, dt_s: float) -> None:
        """Sightings of the reported category (N, T) become or update candidates; close looks identify them."""
        scen = self.scen
        unresolved_before = self.status == UNRESOLVED
        new = sighted & ((self.status == NONE) | (self.status == LOST))
        self._new_candidate = new.any(axis=1)
        if new.any():  # how likely the sighting is the victim, to the crew: its cell's belief against the best one
            cells = self.belief.shape[1]
            cell = belief_logic.cell_size_m(scen.area, cells)[:, None, :]
            water = self.targets - (scen.area[:, 0::2] + self.belief_offset)[:, None, :]
            index = np.clip(np.floor(water / cell), 0, cells - 1).astype(np.int64)
            at_sighting = self.belief[self._arange[:, None], index[..., 0], index[..., 1]]
            best = self.belief.max(axis=(1, 2))[:, None]
            ratio = np.divide(at_sighting, best, out=np.zeros_like(at_sighting), where=best > 0.0)
            self.plausibility[new] = ratio[new].clip(0.0, 1.0)
            self.status[new] = UNRESOLVED
        keep = sighted & (self.status != REJECTED)
        self.sighting[keep] = self.targets[keep]
        self.sighted_s[keep] = np.broadcast_to(self.time_s[:, None], keep.shape)[keep]
        self.unseen_look_s[sighted] = 0.0

        slow = (self.speed_mps <= CLOSE_LOOK_SPEED_MPS)[:, None]
        size = scen.target_size_m * IDENTIFY_SIZE_FACTOR
        identify = search.detection_probability_from_factors(self.position, self.targets, size,
                                                             scen.detection_factor, self.altitude, zoom, intensity)
        elapsed = (self.time_s[:, None] - self.sighted_s)[:, :, None]
        estimates = self.sighting + scen.forecast_drift[:, None, :] * elapsed
        expected = search.detection_probability_from_factors(self.position, estimates, size, scen.detection_factor,
                                                             self.altitude, zoom, intensity) * slow * unresolved_before
        self._identify_chance = 1.0 - np.prod(1.0 - expected, axis=1)
        draws = keyed_uniforms(self.episode_seed ^ IDENTIFY_STREAM, self.steps, self.max_targets)
        identified = unresolved_before & slow & (draws < identify)
        victim = np.zeros_like(identified)
        victim[self._arange, scen.primary_index] = True
        self.status[identified & victim] = CONFIRMED
        self.status[identified & ~victim] = REJECTED

        # Hovering over where a candidate should be without sighting it: after LOST_AFTER_S it is lost.
        near = np.hypot(*(estimates - self.position[:, None, :]).transpose(2, 0, 1))
        looking = (self.status == UNRESOLVED) & ~sighted & slow & (near <= self.flight.reach_radius_m)
        self.unseen_look_s[looking] += dt_s
        self.status[looking & (self.unseen_look_s >= LOST_AFTER_S)] = LOST

    def drift_map(self, dt_s: float) -> None:
        """Move the map ``dt_s`` seconds on with the forecast drift, and blur it for the forecast's error when a blur
        is due at ``time_s`` (the clock already moved on)."""
        belief_logic.drift((self.belief, self.coverage), self.belief_offset, self.scen.area, self.scen.forecast_drift,
                           dt_s)
        self._blur_for_forecast_error()

    def _blur_for_forecast_error(self) -> None:
        due = self.time_s - self.blurred_s >= belief_logic.BLUR_EVERY_S
        if not due.any():
            return
        sigma2 = belief_logic.FORECAST_SIGMA_MPS ** 2
        added_m2 = sigma2 * (self.time_s ** 2 - self.blurred_s ** 2) * due
        cell = belief_logic.cell_size_m(self.scen.area, self.belief.shape[1])
        belief_logic.blur(self.belief, added_m2[:, None] / cell ** 2)
        self.blurred_s[due] = self.time_s[due]

    def close_look(self) -> np.ndarray:
        """(N,) bool: an unresolved, reachable candidate's estimate lies within the reach radius: the camera comes
        down for a close look (``altitude_target``)."""
        near = np.hypot(*(self.candidate_estimates() - self.position[:, None, :]).transpose(2, 0, 1))
        return ((self.candidate_kind() == 1) & (near <= self.flight.reach_radius_m)).any(axis=1)

    @property
    def energy_left(self) -> np.ndarray:
        """(N,) share of the sortie's endurance still left (1 when unlimited)."""
        return np.clip(1.0 - self.time_s / self.scen.endurance_s, 0.0, 1.0)

    @property
    def covered_cells(self) -> np.ndarray:
        """(N,) cells searched to a cumulative probability of detection of at least one half."""
        return (self.coverage >= 0.5).sum(axis=(1, 2))

    @property
    def coverage_ratio(self) -> np.ndarray:
        return self.covered_cells / self.coverage[0].size

    @property
    def searched_cells(self) -> np.ndarray:
        """(N,) the sum of the cells' cumulative probabilities of detection (what the coverage bonus counts), in cells
        of the default 32 x 32 grid (1/1024 of the area each) whatever the map's own cells."""
        return self.coverage.sum(axis=(1, 2)) * (search.GRID_SIZE / self.coverage.shape[1]) ** 2
