"""SarSearch-v1's scripted searchers, vectorised over a batch: the strongest scripted methods built on what a crew
knows (area, charted danger zones, datum and its forecast drift, conditions, own position, own sightings, the
belief of ``missions.belief``), never the hidden victim. SarSearch-v0's are in ``policies.env.baselines_v0``.

Every searcher shares the same rules around its search pattern (:class:`ScriptedSearch`):

* **confirm, then reach**: a candidate identified as the victim is flown to; otherwise the nearest unresolved
  candidate at least ``investigate_plausibility`` plausible is flown to, and over it the drone hovers with the
  camera at ``close_look_zoom`` (the search logic takes the camera down for the close look) until it resolves;
* **bingo**: once the endurance left is no more than the way home at full speed plus ``reserve_s``, the drone flies
  home and hovers there (which ends the sortie with its reserve);
* every point is kept 20 m inside the geofence and routed around the danger zones (``missions.goals``);
* the pattern itself flies at full speed, sensor on, camera at its widest (the widest sweep).

The patterns:

* ``expanding_square``: IAMSAR's expanding square from the drifting datum, legs S, S, 2S, 2S, ... turning right,
  bounded: once its half side passes ``bound_sigmas`` datum sigmas it starts again from the datum, offset by S/2
  (the second pass flies the lanes between the first's); repeated until the sortie ends;
* ``parallel_track``: IAMSAR's parallel track over the box of +- ``bound_sigmas`` datum sigmas round the drifting
  datum, tracks S apart from the corner nearest the drone, repeated with the tracks offset by S/2;
* ``greedy_bayes``: the cell with the most belief per travel time, belief / (distance / speed + ``travel_time_s``),
  flown to and kept until reached or searched down to half its belief, then the next.

Track spacing S = W / ``coverage_factor`` with W the effective sweep width of the camera for the reported object
in the scenario's conditions (``missions.sweep_width``: IAMSAR's coverage factor C = W / S). The settings are
tuned on the val split (``benchmarks/tune_baselines.py``; the defaults are its choice, docs/results/README.md).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np

from missions import goals as goal_logic
from missions import search
from missions.belief_search import arrival_speed_fraction
from missions.sweep_width import sweep_width_m
from missions.validation import check_fields

if TYPE_CHECKING:
    from policies.env.ambiguous import AmbiguousSearchBatch

MAX_WAYPOINTS = 256


def fly_straight(position: np.ndarray, goal: np.ndarray, flight, zoom: float | np.ndarray,
                 turn: Callable | None = None) -> np.ndarray:
    """(N, 4) actions flying from ``position`` straight at ``goal`` (both (N, 2) metres) at full speed, slowing over
    the last step so as to stop on the point instead of overshooting it, with the sensor on and the camera at
    ``zoom``. ``turn(position, direction, step_m)`` may bend the unit direction (hazard avoidance)."""
    offset = goal - position
    distance = np.hypot(*offset.T)
    step_m = flight.max_speed_mps * flight.step_period_s
    speed_fraction = arrival_speed_fraction(distance, flight.max_speed_mps, flight.step_period_s, steps=1.0)
    direction = offset / np.maximum(distance, 1e-9)[:, None]
    if turn is not None:
        direction = turn(position, direction, step_m)
    actions = np.zeros((len(position), 4))
    actions[:, 0:2] = direction * speed_fraction[:, None]
    actions[:, 2] = 1.0
    actions[:, 3] = zoom
    return actions


@dataclass(frozen=True)
class ScriptedSettings:
    """The knobs of the scripted searchers (tuned on the val split)."""

    coverage_factor: float = 1.0
    """IAMSAR's coverage factor C = W / S: the track spacing is the sweep width over it. Allowed [0.25, 4]."""
    bound_sigmas: float = 2.5
    """Patterns: half side of the expanding square / the parallel-track box, in datum sigmas. Allowed [0.5, 10]."""
    investigate_plausibility: float = 0.0
    """Candidates at least this plausible (``BeliefSearchState.plausibility``) are looked at. Allowed [0, 1]."""
    close_look_zoom: float = 0.5
    """Zoom while hovering over a candidate. Allowed [0, 1]."""
    reserve_s: float = 60.0
    """Bingo: head home when the endurance left is the way home plus this (s). Allowed [0, 3600]."""
    travel_time_s: float = 30.0
    """Greedy Bayes: tau in belief / (travel time + tau) (s). Allowed [1, 3600]."""

    def __post_init__(self) -> None:
        check_fields(self, (("coverage_factor", 0.25, 4.0), ("bound_sigmas", 0.5, 10.0),
                            ("investigate_plausibility", 0.0, 1.0), ("close_look_zoom", 0.0, 1.0),
                            ("reserve_s", 0.0, 3600.0), ("travel_time_s", 1.0, 3600.0)))


class ScriptedSearch:
    """The shared rules (module docstring) around a search point that each pattern supplies."""

    def __init__(self, core: "AmbiguousSearchBatch", settings: ScriptedSettings = ScriptedSettings()):
        self.core, self.settings = core, settings
        self.going_home = np.zeros(core.n, dtype=bool)
        self.started = np.full(core.n, -1, dtype=np.int64)  # the episode (by seed) each slot was planned for

    def search_point(self, fresh: np.ndarray) -> np.ndarray:
        """(N, 2) where the pattern flies now; ``fresh`` (N,) marks slots whose episode just started."""
        raise NotImplementedError

    def spacing_m(self, rows: np.ndarray) -> np.ndarray:
        """Track spacing S (m) of these slots: the sweep width for the reported object over the coverage factor."""
        core, flight = self.core, self.core.flight
        reported = core.scen.primary_index[rows]
        width = sweep_width_m(flight.altitude_m, 0.0, flight.max_speed_mps, flight.step_period_s,
                              core.scen.target_size_m[rows, reported], core.scen.detection_factor[rows, reported])
        return width / self.settings.coverage_factor

    def act(self) -> np.ndarray:
        core, settings, flight = self.core, self.settings, self.core.flight
        fresh = (core.steps == 0) | (self.started != core.episode_seed.astype(np.int64))
        self.started[fresh] = core.episode_seed[fresh].astype(np.int64)
        self.going_home[fresh] = False
        point = self.search_point(fresh)
        estimates, kind = core.candidate_estimates(), core.candidate_kind()
        worth = (kind == 2) | ((kind == 1) & (core.plausibility >= settings.investigate_plausibility))
        candidate, has_candidate = goal_logic.candidate_point(core.position, estimates, np.where(worth, kind, 0))
        point = np.where(has_candidate[:, None], candidate, point)
        home = core.scen.start
        left_s = core.energy_left * core.scen.endurance_s
        self.going_home |= left_s - np.hypot(*(core.position - home).T) / flight.max_speed_mps <= settings.reserve_s
        point = np.where(self.going_home[:, None], home, point)
        area = core.scen.area
        point[:, 0] = np.clip(point[:, 0], area[:, 0] + goal_logic.FENCE_MARGIN_M, area[:, 1] - goal_logic.FENCE_MARGIN_M)
        point[:, 1] = np.clip(point[:, 1], area[:, 2] + goal_logic.FENCE_MARGIN_M, area[:, 3] - goal_logic.FENCE_MARGIN_M)
        routed = goal_logic.route_around_hazards(core.position, point, core.scen.obstacles, core.scen.obstacle_valid,
                                                 area)
        looking = has_candidate & ~self.going_home & (np.hypot(*(candidate - core.position).T) <= flight.reach_radius_m)
        zoom = np.where(looking, settings.close_look_zoom, 0.0)
        actions = fly_straight(core.position, routed, flight, zoom)
        # over a candidate or home: hold still (a close look needs a steady camera; home is where it lands)
        hold = looking | (self.going_home & (np.hypot(*(core.position - home).T) <= flight.reach_radius_m))
        actions[hold, 0:2] = np.clip((routed - core.position)[hold] / (flight.max_speed_mps * 4.0), -0.2, 0.2)
        return actions


class WaypointPattern(ScriptedSearch):
    """A pattern of waypoints relative to the drifting datum, followed in order and repeated."""

    def __init__(self, core: "AmbiguousSearchBatch", settings: ScriptedSettings = ScriptedSettings()):
        super().__init__(core, settings)
        self.waypoints = np.zeros((core.n, MAX_WAYPOINTS, 2))
        self.count = np.ones(core.n, dtype=np.int64)
        self.next = np.zeros(core.n, dtype=np.int64)

    def plan(self, rows: np.ndarray) -> list[np.ndarray]:
        """Each slot's waypoints (W, 2), metres from the datum, for these rows."""
        raise NotImplementedError

    def search_point(self, fresh: np.ndarray) -> np.ndarray:
        core = self.core
        rows = np.flatnonzero(fresh)
        if len(rows):
            for row, points in zip(rows, self.plan(rows)):
                points = points[:MAX_WAYPOINTS]
                self.waypoints[row, :len(points)] = points
                self.count[row], self.next[row] = max(len(points), 1), 0
        datum, index = core.scen.datum_at(core.time_s), np.arange(core.n)
        goal = self.waypoints[index, self.next] + datum
        arrived = np.hypot(*(goal - core.position).T) < 0.5 * core.flight.max_speed_mps * core.flight.step_period_s + 1.0
        self.next = np.where(arrived, (self.next + 1) % self.count, self.next)  # the pattern repeats
        return self.waypoints[index, self.next] + datum


class ExpandingSquare(WaypointPattern):
    def plan(self, rows: np.ndarray) -> list[np.ndarray]:
        spacing = self.spacing_m(rows)
        bound = self.settings.bound_sigmas * self.core.scen.datum_sigma[rows]
        plans = []
        for s, limit in zip(spacing, bound):
            passes = []
            for start in (np.zeros(2), np.full(2, s / 2.0)):  # the second pass flies between the first's lanes
                points, leg, heading = [start], 1, 0
                headings = np.array([(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)])  # N, E, S, W: turning right
                while np.abs(points[-1] - start).max() <= limit and len(points) < MAX_WAYPOINTS // 2:
                    points.append(points[-1] + headings[heading % 4] * leg * s)
                    if heading % 2 == 1:
                        leg += 1
                    heading += 1
                passes.append(np.array(points))
            plans.append(np.concatenate(passes))
        return plans


class ParallelTrack(WaypointPattern):
    def plan(self, rows: np.ndarray) -> list[np.ndarray]:
        core = self.core
        spacing = self.spacing_m(rows)
        plans = []
        for row, s in zip(rows, spacing):
            area, datum = core.scen.area[row], core.scen.datum[row]
            half = self.settings.bound_sigmas * core.scen.datum_sigma[row]
            margin = goal_logic.FENCE_MARGIN_M
            south, north = max(area[0] + margin, datum[0] - half), min(area[1] - margin, datum[0] + half)
            west, east = max(area[2] + margin, datum[1] - half), min(area[3] - margin, datum[1] + half)
            start = core.position[row] - datum
            from_north = start[0] > (south + north) / 2.0 - datum[0]
            points = []
            for shift in (0.5, 1.0):  # the second pass flies between the first's tracks
                tracks = np.arange(south + shift * s, north, s)
                if from_north:
                    tracks = tracks[::-1]
                west_first = abs(start[1] + datum[1] - west) <= abs(start[1] + datum[1] - east)
                for k, track in enumerate(tracks):
                    ends = (west, east) if (k % 2 == 0) == west_first else (east, west)
                    points += [(track, ends[0]), (track, ends[1])]
            plans.append(np.array(points) - datum if points else np.zeros((1, 2)))
        return plans


class GreedyBayes(ScriptedSearch):
    """The cell with the most belief per travel time, kept until reached or half searched (module docstring)."""

    def __init__(self, core: "AmbiguousSearchBatch", settings: ScriptedSettings = ScriptedSettings()):
        super().__init__(core, settings)
        self.cell = np.full(core.n, -1, dtype=np.int64)
        self.cell_belief = np.zeros(core.n)

    def search_point(self, fresh: np.ndarray) -> np.ndarray:
        core, flight = self.core, self.core.flight
        n, grid = core.n, search.GRID_SIZE
        north, east = goal_logic.cell_centres(core.scen.area, grid)
        north, east = north + core.belief_offset[:, 0:1], east + core.belief_offset[:, 1:2]
        flat = core.belief.reshape(n, -1)
        index = np.arange(n)
        current = np.stack([north[index, self.cell // grid], east[index, self.cell % grid]], axis=1)
        reached = np.hypot(*(current - core.position).T) <= flight.reach_radius_m
        searched = flat[index, self.cell] < 0.5 * self.cell_belief
        choose = fresh | (self.cell < 0) | reached | searched
        if choose.any():
            rows = np.flatnonzero(choose)
            best = self.choose_cells(rows, north, east)
            self.cell[rows], self.cell_belief[rows] = best, flat[rows, best]
            current[rows] = np.stack([north[rows, best // grid], east[rows, best % grid]], axis=1)
        return current

    def travel_s(self, rows: np.ndarray, north: np.ndarray, east: np.ndarray) -> np.ndarray:
        """(len(rows), G, G): the flight time at full speed from each of these slots to every cell centre."""
        core = self.core
        return np.hypot(north[rows, :, None] - core.position[rows, 0, None, None],
                        east[rows, None, :] - core.position[rows, 1, None, None]) / core.flight.max_speed_mps

    def choose_cells(self, rows: np.ndarray, north: np.ndarray, east: np.ndarray) -> np.ndarray:
        """The flat index of the cell each of these slots flies to next: the most belief per travel time."""
        belief = self.core.belief[rows]
        score = np.log(np.maximum(belief, 1e-300)) - np.log(self.travel_s(rows, north, east)
                                                            + self.settings.travel_time_s)
        return score.reshape(len(rows), -1).argmax(axis=1)


class RandomSearch:
    """Uniform random actions from a seeded generator."""

    def __init__(self, core: "AmbiguousSearchBatch", settings: ScriptedSettings | None = None, seed: int = 0):
        self.core = core
        self.rng = np.random.default_rng(seed)

    def act(self) -> np.ndarray:
        return self.rng.uniform(np.array([-1.0, -1.0, 0.0, 0.0]), 1.0, size=(self.core.n, 4))


BASELINES: dict[str, Callable[..., object]] = {
    "random": RandomSearch,
    "expanding_square": ExpandingSquare,
    "parallel_track": ParallelTrack,
    "greedy_bayes": GreedyBayes,
}
"""SarSearch-v1's scripted searchers by name; each takes (core, settings)."""


TUNED: dict[str, ScriptedSettings] = {
    # python benchmarks/tune_baselines.py --episodes 500 [--only NAME]: 500 val scenarios, two passes of coordinate
    # descent, at most 1 % ran dry (benchmarks/results/tune_baselines.json, tune_parallel_track.json,
    # tune_greedy_bayes.json); val success with these settings in the comments.
    "expanding_square": ScriptedSettings(  # val success 80.0%
        coverage_factor=1.7, bound_sigmas=2.0,
        investigate_plausibility=0.02, close_look_zoom=0.3, reserve_s=20.0, travel_time_s=30.0),
    "parallel_track": ScriptedSettings(  # val success 70.2%
        coverage_factor=0.6, bound_sigmas=1.5,
        investigate_plausibility=0.0, close_look_zoom=0.5, reserve_s=20.0, travel_time_s=30.0),
    "greedy_bayes": ScriptedSettings(  # val success 86.2%
        coverage_factor=1.0, bound_sigmas=2.5,
        investigate_plausibility=0.0, close_look_zoom=0.5, reserve_s=20.0, travel_time_s=30.0),
}
"""Each searcher's settings as chosen on the val split (``benchmarks/tune_baselines.py``); absent: the defaults."""
