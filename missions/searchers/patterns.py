"""The pattern searchers: IAMSAR's expanding square and parallel track, as waypoints relative to the drifting datum
(``WaypointPattern``), and uniform random actions (``RandomSearch``, the floor of every comparison)."""
from __future__ import annotations

import numpy as np

from missions import goals as goal_logic
from missions.search_state_v1 import BeliefSearchState
from missions.searchers.rules import ScriptedSearch, ScriptedSettings

MAX_WAYPOINTS = 256
"""The most waypoints of one pattern's plan (both passes)."""

class WaypointPattern(ScriptedSearch):
    """A pattern of waypoints relative to the drifting datum, followed in order and repeated."""

    def __init__(self, core: BeliefSearchState, settings: ScriptedSettings = ScriptedSettings()):
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

    def __init__(self, core: BeliefSearchState, settings: ScriptedSettings | None = None, seed: int = 0):
        self.core = core
        self.rng = np.random.default_rng(seed)

    def act(self) -> np.ndarray:
        return self.rng.uniform(np.array([-1.0, -1.0, 0.0, 0.0]), 1.0, size=(self.core.n, 4))
