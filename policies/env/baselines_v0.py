"""SarSearch-v0's scripted search baselines over the environment's action space (vectorised over a batch).

They use only what a real crew knows: the search area, the datum and its uncertainty, their own position
and their own detections (the last detection of the victim), never the hidden victim location.

* ``random``: uniform actions.
* ``expanding_square``: IAMSAR expanding square search from the datum: legs of S, S, 2S, 2S, 3S, 3S, ...
  turning right each time, with track spacing S = 1.8 x the footprint half-width (10 % overlap).
* ``parallel_track``: IAMSAR parallel track ("lawnmower") search of the box of +-2.5 sigma around the datum,
  east-west tracks S apart, starting from the corner nearest to the drone.

Both patterns drift with the datum (the forecast current plus the reported object's leeway, as IAMSAR plans
a search of a drifting object) and fly at full speed with the sensor on and the camera at its widest; once the victim
has been detected fly straight to the last detection. Like a real crew they know the charted hazards and the
search-area boundary: waypoints are kept 20 m inside the geofence, and a leg that would enter a danger zone
(plus a 15 m margin) is flown around it along its edge.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Callable

import numpy as np

from missions import search
from missions.searchers import fly_straight

if TYPE_CHECKING:
    from policies.env.task_v0 import SarSearchBatch

TRACK_SPACING_FACTOR = 1.8
PARALLEL_TRACK_SIGMAS = 2.5
MAX_WAYPOINTS = 128
ZOOM = 0.0
FENCE_MARGIN_M = 20.0
HAZARD_MARGIN_M = 15.0


class ScriptedSearch:
    """Base: a per-environment waypoint list, followed at full speed; the victim's detection overrides it."""

    def __init__(self, core: "SarSearchBatch"):
        self.core = core
        self.waypoints = np.zeros((core.n, MAX_WAYPOINTS, 2))
        self.count = np.zeros(core.n, dtype=np.int64)
        self.next = np.zeros(core.n, dtype=np.int64)
        self.spacing_m = TRACK_SPACING_FACTOR * float(search.footprint_half_width_m(core.flight.altitude_m, ZOOM))
        self.planned_episode = np.full(core.n, -1, dtype=np.int64)

    def plan(self, index: int) -> np.ndarray:
        """The waypoints of environment ``index`` for its current episode, (W, 2) north/east metres."""
        raise NotImplementedError

    def act(self) -> np.ndarray:
        core = self.core
        # (re)plan environments that started a new episode since the last call
        fresh = core.steps == 0
        for i in np.flatnonzero(fresh | (self.count == 0)):
            points = self.plan(int(i))[:MAX_WAYPOINTS]
            self.waypoints[i, : len(points)] = points
            self.count[i], self.next[i] = len(points), 0
        position = core.position
        index = np.arange(core.n)
        drift = core.scen.datum_at(core.time_s) - core.scen.datum  # the pattern moves with the drifting datum
        goal = self.waypoints[index, np.minimum(self.next, self.count - 1)] + drift
        arrived = np.hypot(*(goal - position).T) < 0.5 * core.flight.max_speed_mps * core.flight.step_period_s + 1.0
        self.next += arrived & (self.next < self.count - 1)
        goal = self.waypoints[index, self.next] + drift
        goal = np.where(core.has_detection[:, None], core.last_detection, goal)
        fence = core.scen.fence
        goal[:, 0] = np.clip(goal[:, 0], fence[:, 0] + FENCE_MARGIN_M, fence[:, 1] - FENCE_MARGIN_M)
        goal[:, 1] = np.clip(goal[:, 1], fence[:, 2] + FENCE_MARGIN_M, fence[:, 3] - FENCE_MARGIN_M)
        return fly_straight(position, goal, core.flight, ZOOM, turn=self._avoid_hazards)


    def _avoid_hazards(self, position: np.ndarray, direction: np.ndarray, step_m: float) -> np.ndarray:
        """Turn onto the tangent of the nearest danger zone that the next step would enter (inflated by the
        margin), on the side closer to the wanted direction."""
        obstacles, valid = self.core.scen.obstacles, self.core.scen.obstacle_valid
        ahead = position + direction * step_m
        dn = ahead[:, None, 0] - obstacles[:, :, 0]
        de = ahead[:, None, 1] - obstacles[:, :, 1]
        clearance = np.hypot(dn, de) - (obstacles[:, :, 2] + HAZARD_MARGIN_M)
        clearance = np.where(valid, clearance, np.inf)
        nearest = clearance.argmin(axis=1)
        rows = np.arange(len(position))
        blocked = clearance[rows, nearest] < 0.0
        if not blocked.any():
            return direction
        centre = obstacles[rows, nearest, :2]
        radial = position - centre
        radial /= np.maximum(np.hypot(*radial.T), 1e-9)[:, None]
        tangent = np.stack([-radial[:, 1], radial[:, 0]], axis=1)  # one way round
        tangent *= np.where(np.einsum("ij,ij->i", tangent, direction) >= 0.0, 1.0, -1.0)[:, None]
        return np.where(blocked[:, None], tangent, direction)


class ExpandingSquare(ScriptedSearch):
    def plan(self, index: int) -> np.ndarray:
        datum = self.core.scen.datum[index]
        points = [datum]
        headings = ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))  # N, E, S, W: turning right
        leg = 1
        for turn in range(MAX_WAYPOINTS - 1):
            step = np.array(headings[turn % 4]) * leg * self.spacing_m
            points.append(points[-1] + step)
            if turn % 2 == 1:
                leg += 1
        return np.array(points)


class ParallelTrack(ScriptedSearch):
    def plan(self, index: int) -> np.ndarray:
        core = self.core
        area, datum = core.scen.area[index], core.scen.datum[index]
        half_box = PARALLEL_TRACK_SIGMAS * core.scen.datum_sigma[index]
        south, north = max(area[0], datum[0] - half_box), min(area[1], datum[0] + half_box)
        west, east = max(area[2], datum[1] - half_box), min(area[3], datum[1] + half_box)
        tracks = np.arange(south + self.spacing_m / 2, north, self.spacing_m)
        if core.position[index, 0] > (south + north) / 2:  # start from the nearer end
            tracks = tracks[::-1]
        start_west = abs(core.position[index, 1] - west) <= abs(core.position[index, 1] - east)
        points = []
        for k, track in enumerate(tracks):
            ends = (west, east) if (k % 2 == 0) == start_west else (east, west)
            points += [(track, ends[0]), (track, ends[1])]
        return np.array(points) if points else datum[None, :]


class RandomSearch:
    """Uniform random actions from a seeded generator."""

    def __init__(self, core: "SarSearchBatch", seed: int = 0):
        self.core = core
        self.rng = np.random.default_rng(seed)

    def act(self) -> np.ndarray:
        low = np.array([-1.0, -1.0, 0.0, 0.0])
        return self.rng.uniform(low, 1.0, size=(self.core.n, 4))


BASELINES_V0: dict[str, Callable[["SarSearchBatch"], object]] = {
    "random": RandomSearch,
    "expanding_square": ExpandingSquare,
    "parallel_track": ParallelTrack,
}
