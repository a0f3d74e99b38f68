"""The state of N searches in progress, advanced one decision step at a time: what training and flight share.

The training environment (``policies.env.core``) and the mission runner (``autonomy.runner``) both keep a
:class:`SearchState`; they differ only in where the drone's position comes from (the exact dynamics in
training, the Kalman-filtered telemetry in flight). One step, :meth:`SearchState.advance`, given the position
the drone reached and the sensor settings it flew with:

1. objects drift (current + leeway x wind);
2. the camera footprint marks coverage (sensor on) and may detect objects: Bernoulli draws from a
   counter-based generator keyed by (episode seed, step), so each search has its own reproducible stream and
   the same scenario, seed and path give the same detections in training and in flight;
3. the victim's last detection (or, until then, the drifting datum) is updated;
4. end conditions: the victim reached, a danger zone entered, the geofence left;
5. a goal whose point was reached is grounded again (``missions.goals``; points are routed around the charted
   danger zones).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from missions import goals as goal_logic
from missions import search
from missions.goals import NO_GOAL
from missions.mission import FlightSettings
from missions.scenario import CATEGORIES


def splitmix64(x: np.ndarray) -> np.ndarray:
    """A fast, well-mixed 64-bit hash (SplitMix64 finaliser); uint64 arithmetic wraps on purpose."""
    with np.errstate(over="ignore"):
        z = x + np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return z ^ (z >> np.uint64(31))


def keyed_uniforms(seeds: np.ndarray, steps: np.ndarray, count: int) -> np.ndarray:
    """(N, count) uniforms in [0, 1), a pure function of (seed, step, index): same key, same numbers."""
    with np.errstate(over="ignore"):
        key = seeds.astype(np.uint64) * np.uint64(0xD1B54A32D192ED03) + steps.astype(np.uint64) * np.uint64(count)
        bits = splitmix64(key[:, None] + np.arange(count, dtype=np.uint64)[None, :])
    return (bits >> np.uint64(11)) * (1.0 / 9007199254740992.0)


def checked_goals(goals, mask: np.ndarray | None, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Goal indices broadcast to (n,) and the mask of the searches they are for (all by default); a ValueError
    when a masked index is not one of GOAL_NAMES'."""
    goals = np.broadcast_to(np.asarray(goals, dtype=np.int64), (n,))
    mask = np.ones(n, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    if np.any((goals[mask] < 0) | (goals[mask] >= len(goal_logic.GOAL_NAMES))):
        raise ValueError(f"goal indices must be in [0, {len(goal_logic.GOAL_NAMES) - 1}], got {goals[mask]}")
    return goals, mask


@dataclass
class StepOutcome:
    """What one :meth:`SearchState.advance` found, per search (N,) arrays; views valid until the next step."""

    success: np.ndarray
    collision: np.ndarray
    out_of_bounds: np.ndarray
    distance_to_victim_m: np.ndarray
    goal_reached: np.ndarray
    goal_moved_on: np.ndarray
    """Reached, and the goal grounded again points more than the reach radius away: the search moved on (an
    unsearched cell reached with the sensor off stays unsearched, and its goal grounds to the same point)."""
    step_goal_point: np.ndarray
    """(N, 2) the goal point this step flew towards (before any re-grounding)."""
    first_detection_chance: np.ndarray
    """The probability that this step detected the victim for the first time: its detection probability this
    step where it had not been detected before, else 0 (the expected value of the first-detection event)."""


class SearchState:
    """N searches: scenario arrays, drifting objects, coverage, detections and the current goal; see the module
    docstring. ``scen`` is a padded :class:`missions.search.ScenarioBatch` with one row per search."""

    def __init__(self, scen: search.ScenarioBatch, flight: FlightSettings):
        self.scen = scen
        self.flight = flight
        self.n = n = len(scen.datum)
        self.max_targets = scen.targets.shape[1]
        self.position = np.zeros((n, 2))
        self.targets = np.zeros((n, self.max_targets, 2))
        self.time_s = np.zeros(n)
        self.steps = np.zeros(n, dtype=np.int64)
        self.episode_seed = np.zeros(n, dtype=np.uint64)
        self.coverage = np.zeros((n, search.GRID_SIZE, search.GRID_SIZE), dtype=np.float32)
        self.covered_cells = np.zeros(n, dtype=np.int64)
        self.detections = np.zeros((n, len(CATEGORIES)), dtype=bool)
        self.last_detection = np.zeros((n, 2))
        self.has_detection = np.zeros(n, dtype=bool)
        self.first_detection_step = np.full(n, -1, dtype=np.int64)
        self.goal = np.full(n, NO_GOAL, dtype=np.int64)
        self.goal_point = np.zeros((n, 2))
        self._arange = np.arange(n)

    def reset(self, indices: np.ndarray, episode_seeds: np.ndarray) -> None:
        """Start the searches ``indices`` (whose ``scen`` rows are already set) from their start points."""
        scen = self.scen
        self.targets[indices] = scen.targets[indices]
        self.position[indices] = scen.start[indices]
        self.time_s[indices] = 0.0
        self.steps[indices] = 0
        self.episode_seed[indices] = episode_seeds
        self.coverage[indices] = 0.0
        self.covered_cells[indices] = 0
        self.detections[indices] = False
        self.last_detection[indices] = scen.datum[indices]
        self.has_detection[indices] = False
        self.first_detection_step[indices] = -1
        self.goal[indices] = NO_GOAL
        self.goal_point[indices] = scen.datum[indices]

    def set_goals(self, goals: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """Give searches a meta-controller goal (index into GOAL_NAMES) and ground it now; returns the mask."""
        goals, mask = checked_goals(goals, mask, self.n)
        self.goal[mask] = goals[mask]
        self.ground(mask)
        return mask

    def goal_due(self, subgoal_interval: int) -> np.ndarray:
        """(N,) whether each search's meta-controller chooses a goal before the next step: SarSearch-v0's cadence,
        every K steps of the episode (``missions.goals.goal_due``)."""
        return goal_logic.goal_due(self.steps, subgoal_interval)

    def ground(self, mask: np.ndarray) -> None:
        """Turn the goals of the ``mask`` rows into points from the search state now."""
        scen = self.scen
        self.goal_point[mask] = goal_logic.ground_goals(
            self.goal[mask], self.position[mask], scen.area[mask], self.coverage[mask],
            scen.datum_at(self.time_s)[mask], scen.datum_sigma[mask], self.last_detection[mask],
            self.has_detection[mask], scen.start[mask], scen.obstacles[mask], scen.obstacle_valid[mask])

    def target_position(self, goal_conditioned: bool) -> np.ndarray:
        """What the observation calls the target, never the hidden victim: the goal's point (HRL-SAC), or the
        last detection, which is the drifting datum until the victim has been seen (flat SAC)."""
        return self.goal_point if goal_conditioned else self.last_detection

    def advance(self, position: np.ndarray, intensity: np.ndarray, zoom: np.ndarray, dt_s: float) -> StepOutcome:
        """One decision step: the drones flew to ``position`` (N, 2) with these sensor settings (N,)."""
        flight, scen = self.flight, self.scen
        self.position[:] = position
        self.time_s += dt_s
        self.steps += 1
        search.drift_targets(self.targets, scen.drift_velocity, dt_s)

        half_width = search.footprint_half_width_m(flight.altitude_m, zoom)
        self.covered_cells += search.cover(self.coverage, scen.area, position, half_width, intensity)
        probability = scen.detection_probability(position, self.targets, flight.altitude_m, zoom, intensity)
        if probability.any():  # the draws are a pure function of (seed, step): skipping them changes nothing
            detected = keyed_uniforms(self.episode_seed, self.steps, self.max_targets) < probability
        else:
            detected = np.zeros(probability.shape, dtype=bool)
        self.detections = search.detected_categories(detected, scen.target_category)
        primary = scen.primary_index
        victim_seen = detected[self._arange, primary]
        self.last_detection[victim_seen] = self.targets[self._arange, primary][victim_seen]
        first_chance = probability[self._arange, primary] * ~self.has_detection
        first = victim_seen & ~self.has_detection
        self.first_detection_step[first] = self.steps[first]
        self.has_detection |= victim_seen
        not_seen = ~self.has_detection  # until the victim is seen, its best estimate is the drifting datum
        self.last_detection[not_seen] = scen.datum_at(self.time_s)[not_seen]

        distance = search.distance_to_primary(position, self.targets, primary)
        success = distance <= flight.reach_radius_m
        collision = search.inside_obstacle(position, scen.obstacles, scen.obstacle_valid) & ~success
        out_of_bounds = search.outside_fence(position, scen.fence) & ~success
        step_goal_point = self.goal_point.copy()
        goal_reached = (self.goal != NO_GOAL) & (np.hypot(*(position - step_goal_point).T) <= flight.reach_radius_m)
        if goal_reached.any():
            self.ground(goal_reached)
        moved_on = goal_reached & (np.hypot(*(self.goal_point - step_goal_point).T) > flight.reach_radius_m)
        return StepOutcome(success, collision, out_of_bounds, distance, goal_reached, moved_on, step_goal_point,
                           first_chance)

    @property
    def coverage_ratio(self) -> np.ndarray:
        return self.covered_cells / self.coverage[0].size

    @property
    def searched_cells(self) -> np.ndarray:
        """(N,) the coverage grid's sum: covered cells (what the low level's coverage bonus counts)."""
        return self.covered_cells
