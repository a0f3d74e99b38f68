"""SarSearch-v1's scripted searchers, vectorised over a batch: the strongest scripted methods built on what a crew
knows (area, charted danger zones, datum and its forecast drift, conditions, own position, own sightings, the
belief of ``missions.belief``), never the hidden victim, by name (``BASELINES``) with the settings tuned for each
(``TUNED``). SarSearch-v0's are in ``policies.env.baselines_v0``.

Every searcher shares the same rules around its search pattern (``policies.env.scripted_v1.ScriptedSearch``):

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
  flown to and kept until reached or searched down to half its belief, then the next;
* ``lookahead_bayes``: greedy Bayes that, each time it chooses a cell, flies ``lookahead_options`` options forward
  in the belief for ``lookahead_s`` (continuing greedily after each) and takes the one whose rollout detects the
  victim most probably by then (:class:`policies.env.lookahead_v1.LookaheadBayes`): a planner on the crew's own
  model, the strongest scripted searcher on the task (docs/results.md).

Track spacing S = W / ``coverage_factor`` with W the effective sweep width of the camera for the reported object
in the scenario's conditions (``missions.sweep_width``: IAMSAR's coverage factor C = W / S). The settings are
tuned on the val split (``benchmarks/tune_baselines.py``; the defaults are its choice).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Callable

import numpy as np

from missions import goals as goal_logic
from policies.env.lookahead_v1 import LookaheadBayes, box_sum, top_cells
from policies.env.scripted_v1 import GreedyBayes, ScriptedSearch, ScriptedSettings, fly_straight

if TYPE_CHECKING:
    from policies.env.task_v1 import AmbiguousSearchBatch

__all__ = ["BASELINES", "TUNED", "ExpandingSquare", "GreedyBayes", "LookaheadBayes", "ParallelTrack", "RandomSearch",
           "ScriptedSearch", "ScriptedSettings", "WaypointPattern", "box_sum", "fly_straight", "top_cells"]

MAX_WAYPOINTS = 256
"""The most waypoints of one pattern's plan (both passes)."""

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
        near_m = 0.5 * core.flight.max_speed_mps * core.flight.step_period_s + 1.0
        arrived = np.hypot(*(goal - core.position).T) < near_m
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
    "lookahead_bayes": LookaheadBayes,
}
"""SarSearch-v1's scripted searchers by name; each takes (core, settings)."""


TUNED: dict[str, ScriptedSettings] = {
    # python benchmarks/tune_baselines.py --episodes 500 [--only NAME]: coordinate descent on val scenarios, with
    # at most 1 % of the sorties running dry (its reports: benchmarks/results/tune_baselines.json,
    # tune_parallel_track.json, tune_greedy_bayes.json)
    "expanding_square": ScriptedSettings(
        coverage_factor=1.7, bound_sigmas=2.0,
        investigate_plausibility=0.02, close_look_zoom=0.3, reserve_s=20.0, travel_time_s=30.0),
    "parallel_track": ScriptedSettings(
        coverage_factor=0.6, bound_sigmas=1.5,
        investigate_plausibility=0.0, close_look_zoom=0.5, reserve_s=20.0, travel_time_s=30.0),
    "greedy_bayes": ScriptedSettings(
        coverage_factor=1.0, bound_sigmas=2.5,
        investigate_plausibility=0.0, close_look_zoom=0.5, reserve_s=20.0, travel_time_s=30.0),
    # greedy Bayes' settings; the horizon and the options chosen on val with benchmarks/decision_ceiling.py
    # --rollouts (docs/results.md)
    "lookahead_bayes": ScriptedSettings(
        coverage_factor=1.0, bound_sigmas=2.5,
        investigate_plausibility=0.0, close_look_zoom=0.5, reserve_s=20.0, travel_time_s=30.0,
        lookahead_s=60.0, lookahead_options=6),
}
"""Each searcher's settings as chosen on the val split (``benchmarks/tune_baselines.py``); absent: the defaults."""
