"""The meta-controller's four goals and how each is grounded to a coordinate from the search state.

HRL-SAC's meta-controller picks one goal every K steps; the low-level policy is then sent to a point g and
rewarded with -||position - g||. Grounding is part of the search logic because the flight runtime must turn
the artifact's goal index into the same point the policy was trained with. All functions work on a batch of
N searches; positions are (north, east) metres in the local NED frame of home.

* ExploreArea: the centre of the most attractive unexplored 8 x 8 block of the coverage grid (blocks are 4 x 4
  cells); attractiveness = uncovered share - 0.5 * distance / area diagonal, among blocks at least half
  uncovered. Falls back to the datum when the whole area is covered.
* SearchSpecificLocation: the uncovered grid cell with the highest prior probability of holding the victim per
  travel: a Gaussian around the datum with the datum's uncertainty, times (1 - coverage), times
  exp(-distance from the drone / 200 m), so that of two almost equally likely cells the nearer is searched first
  instead of crossing the datum back and forth. Falls back to the datum.
* TrackObject: the best estimate of where the victim is now: its last detection, or before any detection the
  SearchSpecificLocation point (the most probable place not yet searched).
* ReturnToBase: home (the start point).

Every goal's point is then routed around the charted danger zones (``route_around_hazards``): when the straight
leg from the drone to the point would pass within ``HAZARD_MARGIN_M`` of a zone, the drone is sent first to a
waypoint beyond the tangent point of that inflated zone, and the goal is grounded again from there on arrival.
The danger zones are charted (they are part of the mission file), the observation does not show them, so the
search logic, not the learned low level, keeps the drone clear of them, as the scripted baselines do.

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


def goal_due(steps, subgoal_interval: int, event=False):
    """Whether the meta-controller chooses a goal now, given the steps flown under the current goal ``steps`` (an
    int or an array; 0 at an episode's start) and whether something happened that calls for a decision ``event``:
    at the start, every K = ``subgoal_interval`` steps after (0, K, 2K, ...), and at once on an event. The one
    statement of the cadence: training, evaluation, the export's parity check and the flight pilot all ask it,
    through the search state's ``goal_due`` (SarSearch-v0 counts the episode's steps and has no events; v1 counts
    from the last decision and has two, ``missions.search_state_v1.BeliefSearchState.decision_event``)."""
    return (steps % subgoal_interval == 0) | event


BLOCKS = 8  # ExploreArea works on an 8 x 8 grid of blocks
DISTANCE_WEIGHT = 0.5
TRAVEL_SCALE_M = 200.0
"""SearchSpecificLocation discounts a cell's probability by exp(-distance / TRAVEL_SCALE_M). Chosen by a quick
look at a few scales (30-400 m) with a scripted low level, not a committed script; with it, the scripted hierarchy
of ``benchmarks/action_ablation.py`` reaches the figure docs/environment.md gives."""
FENCE_MARGIN_M = 20.0
"""Every goal point is kept this far inside the search area (the geofence of training), so that a drone arriving
at full speed does not carry on across the fence."""
HAZARD_MARGIN_M = 20.0
"""Clearance kept from a danger zone's rim by the routed goal points (more than the 15 m reach radius, so a drone
that turns once within reach of a waypoint still clears the zone)."""
EXIT_MARGIN_M = 10.0
"""A drone already inside a zone's margin is first sent this far beyond it, straight away from the centre."""
OUTSIDE_FENCE_COST = 1e9
"""Added to the length of a detour whose waypoint lies beyond the fence margin: the other side is taken."""


def cell_centres(area: np.ndarray, cells: int) -> tuple[np.ndarray, np.ndarray]:
    """(N, cells) north and east coordinates of the centres of a cells x cells grid over each area."""
    fractions = (np.arange(cells) + 0.5) / cells
    north = area[:, 0:1] + fractions[None, :] * (area[:, 1:2] - area[:, 0:1])
    east = area[:, 2:3] + fractions[None, :] * (area[:, 3:4] - area[:, 2:3])
    return north, east


def _distance_to_cells(north: np.ndarray, east: np.ndarray, agent_ne: np.ndarray) -> np.ndarray:
    """(N, R, C) metres from each drone to every cell centre (north (N, R), east (N, C))."""
    return np.hypot(north[:, :, None] - agent_ne[:, 0, None, None], east[:, None, :] - agent_ne[:, 1, None, None])


def _best_point(score: np.ndarray, north: np.ndarray, east: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """The (north, east) of each search's best cell; score is (N, R, C), north (N, R), east (N, C). A search with
    no finite score (nothing left to search) gets its ``fallback`` point instead."""
    n, rows, cols = score.shape
    flat = score.reshape(n, -1)
    best = flat.argmax(axis=1)
    index = np.arange(n)
    point = np.stack([north[index, best // cols], east[index, best % cols]], axis=1)
    nothing_left = ~np.isfinite(flat.max(axis=1))
    point[nothing_left] = fallback[nothing_left]
    return point


def explore_point(agent_ne: np.ndarray, area: np.ndarray, coverage: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    n, grid = coverage.shape[0], coverage.shape[1]
    side = grid // BLOCKS
    uncovered = 1.0 - coverage.reshape(n, BLOCKS, side, BLOCKS, side).mean(axis=(2, 4))
    north, east = cell_centres(area, BLOCKS)
    diagonal = np.hypot(area[:, 1] - area[:, 0], area[:, 3] - area[:, 2])[:, None, None]
    distance = _distance_to_cells(north, east, agent_ne)
    score = np.where(uncovered >= 0.5, uncovered - DISTANCE_WEIGHT * distance / diagonal, -np.inf)
    return _best_point(score, north, east, fallback)


def search_location_point(agent_ne: np.ndarray, area: np.ndarray, coverage: np.ndarray, datum: np.ndarray,
                          datum_sigma: np.ndarray) -> np.ndarray:
    grid = coverage.shape[1]
    north, east = cell_centres(area, grid)
    sigma2 = 2.0 * np.maximum(datum_sigma, 1.0)[:, None, None] ** 2
    # log of prior x travel discount, so that far cells compare without underflowing to 0
    log_score = -((north[:, :, None] - datum[:, 0, None, None]) ** 2
                  + (east[:, None, :] - datum[:, 1, None, None]) ** 2) / sigma2
    log_score -= _distance_to_cells(north, east, agent_ne) / TRAVEL_SCALE_M
    uncovered = 1.0 - coverage
    score = np.where(uncovered > 0.0, log_score + np.log(np.maximum(uncovered, 1e-30)), -np.inf)
    return _best_point(score, north, east, datum)


def route_around_hazards(agent_ne: np.ndarray, point: np.ndarray, obstacles: np.ndarray, obstacle_valid: np.ndarray,
                         area: np.ndarray) -> np.ndarray:
    """(N, 2) points the drone can fly to in a straight line from ``agent_ne`` without passing within
    ``HAZARD_MARGIN_M`` of a danger zone (circles (N, O, 3): north, east, radius) on its way towards ``point``.

    A point inside an inflated zone moves out to its rim. When the straight leg crosses an inflated zone, the
    first one along the leg is passed on the side that makes the shorter way: the waypoint lies on the tangent
    from the drone to the inflated circle, one inflated radius beyond the tangent point. Reaching it grounds the
    goal again (``SearchState.advance``), and so routes it again: several zones are passed one at a time. A drone
    inside an inflated zone, with the zone ahead, leaves it radially first.
    Waypoints are kept ``FENCE_MARGIN_M`` inside the search area: a zone near the fence is passed on the side
    away from it, even when the way round the fence's side would be shorter."""
    out = point.astype(np.float64, copy=True)
    centre, radius = obstacles[:, :, :2], obstacles[:, :, 2] + HAZARD_MARGIN_M
    for k in range(obstacles.shape[1]):  # a point inside an inflated zone: onto its rim
        away = out - centre[:, k]
        distance = np.hypot(*away.T)
        inside = obstacle_valid[:, k] & (distance < radius[:, k])
        unit = away[inside] / np.maximum(distance[inside], 1e-9)[:, None]
        out[inside] = centre[inside, k] + unit * (radius[inside, k] + 1.0)[:, None]
    leg = out - agent_ne
    length = np.maximum(np.hypot(*leg.T), 1e-9)
    along = leg / length[:, None]
    to_centre = centre - agent_ne[:, None, :]
    t = np.einsum("noi,ni->no", to_centre, along)  # how far along the leg each centre lies
    nearest = np.clip(t, 0.0, length[:, None])[:, :, None] * along[:, None, :]
    crosses = obstacle_valid & (t > 0.0) & (np.hypot(*(to_centre - nearest).transpose(2, 0, 1)) < radius)
    rows = np.flatnonzero(crosses.any(axis=1))
    if len(rows) == 0:
        return out
    first = np.where(crosses[rows], t[rows], np.inf).argmin(axis=1)
    c, r, p = centre[rows, first], radius[rows, first], agent_ne[rows]
    from_centre = p - c
    d = np.maximum(np.hypot(*from_centre.T), 1e-9)
    base = np.arctan2(from_centre[:, 1], from_centre[:, 0])
    half_angle = np.arccos(np.minimum(r / d, 1.0))
    inner = area[rows] + np.array([FENCE_MARGIN_M, -FENCE_MARGIN_M, FENCE_MARGIN_M, -FENCE_MARGIN_M])
    best, best_cost = None, None
    for side in (1.0, -1.0):  # the two tangents; keep the one with the shorter way to the point
        angle = base + side * half_angle
        touch = c + r[:, None] * np.stack([np.cos(angle), np.sin(angle)], axis=1)
        heading = touch - p
        heading /= np.maximum(np.hypot(*heading.T), 1e-9)[:, None]
        waypoint = touch + heading * r[:, None]
        cost = np.hypot(*(waypoint - p).T) + np.hypot(*(out[rows] - waypoint).T)
        # A waypoint beyond the fence margin would be pulled inside below, and the leg to it then crosses the zone:
        # the side that fits inside wins, whatever its length (when neither fits, the shorter way still does).
        outside = ((waypoint[:, 0] < inner[:, 0]) | (waypoint[:, 0] > inner[:, 1])
                   | (waypoint[:, 1] < inner[:, 2]) | (waypoint[:, 1] > inner[:, 3]))
        cost = cost + OUTSIDE_FENCE_COST * outside
        best = waypoint if best is None else np.where((cost < best_cost)[:, None], waypoint, best)
        best_cost = cost if best_cost is None else np.minimum(cost, best_cost)
    inside_margin = d <= r
    best[inside_margin] = c[inside_margin] + (from_centre[inside_margin] / d[inside_margin, None]) \
        * (r[inside_margin] + EXIT_MARGIN_M)[:, None]
    best[:, 0] = np.clip(best[:, 0], inner[:, 0], inner[:, 1])
    best[:, 1] = np.clip(best[:, 1], inner[:, 2], inner[:, 3])
    out[rows] = best
    return out


def ground_goals(goal: np.ndarray, agent_ne: np.ndarray, area: np.ndarray, coverage: np.ndarray,
                 datum: np.ndarray, datum_sigma: np.ndarray, last_detection: np.ndarray, has_detection: np.ndarray,
                 home: np.ndarray, obstacles: np.ndarray | None = None,
                 obstacle_valid: np.ndarray | None = None) -> np.ndarray:
    """(N, 2) goal points for goal indices (N,); coverage is the (N, 32, 32) grid. Entries with no goal get the datum.
    With ``obstacles`` (N, O, 3) and ``obstacle_valid`` (N, O), points are routed around those danger zones."""
    point = datum.copy()
    explore = goal == EXPLORE
    if explore.any():
        point[explore] = explore_point(agent_ne[explore], area[explore], coverage[explore], datum[explore])
    track = (goal == TRACK_OBJECT) & has_detection
    search_here = (goal == SEARCH_LOCATION) | ((goal == TRACK_OBJECT) & ~has_detection)
    if search_here.any():
        point[search_here] = search_location_point(agent_ne[search_here], area[search_here], coverage[search_here],
                                                   datum[search_here], datum_sigma[search_here])
    point[track] = last_detection[track]
    home_goal = goal == RETURN_TO_BASE
    point[home_goal] = home[home_goal]
    point[:, 0] = np.clip(point[:, 0], area[:, 0] + FENCE_MARGIN_M, area[:, 1] - FENCE_MARGIN_M)
    point[:, 1] = np.clip(point[:, 1], area[:, 2] + FENCE_MARGIN_M, area[:, 3] - FENCE_MARGIN_M)
    if obstacles is not None:
        point = route_around_hazards(agent_ne, point, obstacles, obstacle_valid, area)
    return point


# ---------------------------------------------------------------------------------------------- SarSearch-v1

BELIEF_FLOOR = 1e-12
"""Cells with less belief than this count as searched out (SearchSpecificLocation falls back to the datum)."""


def belief_point(agent_ne: np.ndarray, area: np.ndarray, belief: np.ndarray, offset: np.ndarray,
                 fallback: np.ndarray) -> np.ndarray:
    """SarSearch-v1's SearchSpecificLocation: the cell with the most belief per travel, log belief - distance /
    TRAVEL_SCALE_M, at its centre where its water is now (``offset``, ``missions.belief``)."""
    grid = belief.shape[1]
    north, east = cell_centres(area, grid)
    north, east = north + offset[:, 0:1], east + offset[:, 1:2]
    log_score = np.log(np.maximum(belief, BELIEF_FLOOR)) - _distance_to_cells(north, east, agent_ne) / TRAVEL_SCALE_M
    score = np.where(belief > BELIEF_FLOOR, log_score, -np.inf)
    return _best_point(score, north, east, fallback)


def candidate_point(agent_ne: np.ndarray, candidates: np.ndarray, kind: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The candidate TrackObject flies to: the confirmed victim if there is one, else the nearest unresolved one
    (``kind`` (N, T): 0 none, 1 unresolved, 2 confirmed; ``candidates`` (N, T, 2) their estimates). Returns the
    points (N, 2) and whether there was any (N,)."""
    distance = np.hypot(*(candidates - agent_ne[:, None, :]).transpose(2, 0, 1))
    score = np.where(kind == 0, np.inf, distance - 1e9 * (kind == 2))
    best = score.argmin(axis=1)
    return candidates[np.arange(len(best)), best], np.isfinite(score.min(axis=1, initial=np.inf))


def ground_goals_v1(goal: np.ndarray, agent_ne: np.ndarray, area: np.ndarray, searched: np.ndarray,
                    belief: np.ndarray, offset: np.ndarray, candidates: np.ndarray, kind: np.ndarray,
                    datum: np.ndarray, home: np.ndarray, obstacles: np.ndarray,
                    obstacle_valid: np.ndarray) -> np.ndarray:
    """SarSearch-v1's goal points (N, 2) for goal indices (N,), from what a crew knows:

    * ExploreArea: the centre of the most attractive block of the area not yet searched (8 x 8 blocks;
      attractiveness = unsearched share - 0.5 * distance / area diagonal, among blocks at least half unsearched;
      searched = the cumulative probability of detection of the looks so far, blind to the prior), where its water
      has drifted to now (``explore_point``); SearchSpecificLocation's point once every block is searched.
    * SearchSpecificLocation: the centre of the belief cell with the most probability of holding the victim per
      travel (log belief - distance from the drone / 200 m), where its water has drifted to now (``belief_point``).
    * TrackObject: the confirmed victim's estimated position, else the nearest candidate not yet identified (a
      sighting of the victim's category, drifted with the water since; ``candidate_point``); without a candidate,
      SearchSpecificLocation's point.
    * ReturnToBase: home (the start point).

    These bullets are what an exported artifact's manifest says of its goals (``policies.export.artifact``).

    Points are kept ``FENCE_MARGIN_M`` inside the area and routed around the danger zones, as in SarSearch-v0."""
    point = datum.copy()
    tracked, has_candidate = candidate_point(agent_ne, candidates, kind)
    track = (goal == TRACK_OBJECT) & has_candidate
    needs_belief = (goal == EXPLORE) | (goal == SEARCH_LOCATION) | ((goal == TRACK_OBJECT) & ~has_candidate)
    if needs_belief.any():
        rows = needs_belief
        point[rows] = belief_point(agent_ne[rows], area[rows], belief[rows], offset[rows], datum[rows])
    explore = goal == EXPLORE
    if explore.any():
        blocks = explore_point(agent_ne[explore], area[explore], searched[explore], point[explore] - offset[explore])
        point[explore] = blocks + offset[explore]
    point[track] = tracked[track]
    home_goal = goal == RETURN_TO_BASE
    point[home_goal] = home[home_goal]
    point[:, 0] = np.clip(point[:, 0], area[:, 0] + FENCE_MARGIN_M, area[:, 1] - FENCE_MARGIN_M)
    point[:, 1] = np.clip(point[:, 1], area[:, 2] + FENCE_MARGIN_M, area[:, 3] - FENCE_MARGIN_M)
    return route_around_hazards(agent_ne, point, obstacles, obstacle_valid, area)
