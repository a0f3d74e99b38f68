"""The meta-controller's four goals and how each is grounded to a coordinate from the search state.

HRL-SAC's meta-controller picks one goal every K steps; the low-level policy is then sent to a point g and
rewarded with -||position - g||. Grounding is part of the search logic because the flight runtime must turn
the artifact's goal index into the same point the policy was trained with. All functions work on a batch of
N searches; positions are (north, east) metres in the local NED frame of home.

* ExploreArea: the centre of the most attractive unexplored 8 x 8 block of the coverage grid (blocks are 4 x 4
  cells); attractiveness = uncovered share - 0.5 * distance / area diagonal, among blocks at least half
  uncovered. Falls back to the datum when the whole area is covered.
* SearchSpecificLocation: the uncovered grid cell with the highest prior probability of holding the victim:
  a Gaussian around the datum with the datum's uncertainty, times (1 - coverage). Falls back to the datum.
* TrackObject: the best estimate of where the victim is now: its last detection, or before any detection the
  SearchSpecificLocation point (the most probable place not yet searched).
* ReturnToBase: home (the start point).

Callers pass the datum drifted to the current time (``ScenarioBatch.datum_at``), and re-ground a goal when the
drone reaches its point before the meta-controller's next decision (``SarSearchBatch.step``): the goal keeps its
meaning ("search the most probable unsearched place") while its point moves on.
"""
from __future__ import annotations

import numpy as np

GOAL_NAMES: tuple[str, ...] = ("ExploreArea", "SearchSpecificLocation", "TrackObject", "ReturnToBase")
NO_GOAL = -1
"""Goal index of a search without a meta-controller goal (flat SAC, or before the first decision)."""
EXPLORE, SEARCH_LOCATION, TRACK_OBJECT, RETURN_TO_BASE = range(4)
BLOCKS = 8  # ExploreArea works on an 8 x 8 grid of blocks
DISTANCE_WEIGHT = 0.5


def cell_centres(area: np.ndarray, cells: int) -> tuple[np.ndarray, np.ndarray]:
    """(N, cells) north and east coordinates of the centres of a cells x cells grid over each area."""
    fractions = (np.arange(cells) + 0.5) / cells
    north = area[:, 0:1] + fractions[None, :] * (area[:, 1:2] - area[:, 0:1])
    east = area[:, 2:3] + fractions[None, :] * (area[:, 3:4] - area[:, 2:3])
    return north, east


def _argmax_point(score: np.ndarray, north: np.ndarray, east: np.ndarray) -> np.ndarray:
    """The (north, east) of each search's best cell; score is (N, R, C), north (N, R), east (N, C)."""
    n, rows, cols = score.shape
    best = score.reshape(n, -1).argmax(axis=1)
    index = np.arange(n)
    return np.stack([north[index, best // cols], east[index, best % cols]], axis=1)


def explore_point(agent_ne: np.ndarray, area: np.ndarray, coverage: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    n, grid = coverage.shape[0], coverage.shape[1]
    side = grid // BLOCKS
    uncovered = 1.0 - coverage.reshape(n, BLOCKS, side, BLOCKS, side).mean(axis=(2, 4))
    north, east = cell_centres(area, BLOCKS)
    diagonal = np.hypot(area[:, 1] - area[:, 0], area[:, 3] - area[:, 2])[:, None, None]
    distance = np.hypot(north[:, :, None] - agent_ne[:, 0, None, None], east[:, None, :] - agent_ne[:, 1, None, None])
    score = np.where(uncovered >= 0.5, uncovered - DISTANCE_WEIGHT * distance / diagonal, -np.inf)
    point = _argmax_point(score, north, east)
    nothing_left = ~np.isfinite(score.reshape(n, -1).max(axis=1))
    point[nothing_left] = fallback[nothing_left]
    return point


def search_location_point(area: np.ndarray, coverage: np.ndarray, datum: np.ndarray, datum_sigma: np.ndarray) -> np.ndarray:
    n, grid = coverage.shape[0], coverage.shape[1]
    north, east = cell_centres(area, grid)
    sigma2 = 2.0 * np.maximum(datum_sigma, 1.0)[:, None, None] ** 2
    prior = np.exp(-((north[:, :, None] - datum[:, 0, None, None]) ** 2
                     + (east[:, None, :] - datum[:, 1, None, None]) ** 2) / sigma2)
    score = prior * (1.0 - coverage)
    point = _argmax_point(score, north, east)
    exhausted = score.reshape(n, -1).max(axis=1) <= 1e-12
    point[exhausted] = datum[exhausted]
    return point


def ground_goals(goal: np.ndarray, agent_ne: np.ndarray, area: np.ndarray, coverage: np.ndarray,
                 datum: np.ndarray, datum_sigma: np.ndarray, last_detection: np.ndarray, has_detection: np.ndarray,
                 home: np.ndarray) -> np.ndarray:
    """(N, 2) goal points for goal indices (N,); coverage is the (N, 32, 32) grid. Entries with no goal get the datum."""
    point = datum.copy()
    explore = goal == EXPLORE
    if explore.any():
        point[explore] = explore_point(agent_ne[explore], area[explore], coverage[explore], datum[explore])
    track = (goal == TRACK_OBJECT) & has_detection
    search_here = (goal == SEARCH_LOCATION) | ((goal == TRACK_OBJECT) & ~has_detection)
    if search_here.any():
        point[search_here] = search_location_point(area[search_here], coverage[search_here], datum[search_here],
                                                   datum_sigma[search_here])
    point[track] = last_detection[track]
    home_goal = goal == RETURN_TO_BASE
    point[home_goal] = home[home_goal]
    return point
