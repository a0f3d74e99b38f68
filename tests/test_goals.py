"""Goal grounding: each of the meta-controller's goals becomes the documented point of the search state."""
from __future__ import annotations

import numpy as np

from missions.goals import (EXPLORE, HAZARD_MARGIN_M, RETURN_TO_BASE, SEARCH_LOCATION, TRACK_OBJECT, TRAVEL_SCALE_M,
                           ground_goals, ground_goals_v1, route_around_hazards)

AREA = np.array([[-50.0, 950.0, -500.0, 500.0]])  # 32 x 32 cells of 31.25 m; 8 x 8 blocks of 125 m


def ground(goal, agent=(0.0, 0.0), coverage=None, datum=(600.0, 100.0), sigma=80.0, detection=None, home=(0.0, 0.0)):
    coverage = np.zeros((1, 32, 32), np.float32) if coverage is None else coverage[None]
    last = np.array([detection if detection is not None else datum])
    return ground_goals(np.array([goal]), np.array([agent]), AREA, coverage, np.array([datum]), np.array([sigma]),
                        last, np.array([detection is not None]), np.array([home]))[0]


def cell_centre(row: int, col: int) -> tuple[float, float]:
    return -50.0 + (row + 0.5) * 31.25, -500.0 + (col + 0.5) * 31.25


def test_return_to_base_is_home():
    np.testing.assert_allclose(ground(RETURN_TO_BASE, agent=(700.0, 300.0), home=(0.0, 0.0)), (0.0, 0.0))


def test_track_object_is_the_last_detection_or_else_the_most_probable_unsearched_place():
    datum = cell_centre(20, 19)
    coverage = np.zeros((32, 32), np.float32)
    coverage[20, 19] = 1.0  # the datum's own cell has been searched
    before = ground(TRACK_OBJECT, coverage=coverage, datum=datum)
    np.testing.assert_allclose(before, ground(SEARCH_LOCATION, coverage=coverage, datum=datum))
    assert np.hypot(*(np.array(before) - datum)) == np.float64(31.25)  # a neighbouring cell
    np.testing.assert_allclose(ground(TRACK_OBJECT, coverage=coverage, datum=datum, detection=(640.0, 80.0)),
                               (640.0, 80.0))


def test_search_location_is_the_most_probable_uncovered_cell_near_the_datum():
    datum = cell_centre(20, 19)
    np.testing.assert_allclose(ground(SEARCH_LOCATION, agent=datum, datum=datum), datum)
    coverage = np.zeros((32, 32), np.float32)
    coverage[19:22, 18:21] = 1.0  # the datum's cell and its neighbours have been searched
    point = np.array(ground(SEARCH_LOCATION, coverage=coverage, datum=datum))
    distance = np.hypot(*(point - datum))
    assert 60.0 < distance < 70.0  # the nearest ring of unsearched cells (2 cells = 62.5 m away)
    np.testing.assert_allclose(ground(SEARCH_LOCATION, coverage=np.ones((32, 32), np.float32), datum=datum), datum)


def test_search_location_prefers_the_nearer_of_two_equally_likely_cells():
    datum = cell_centre(20, 19)
    coverage = np.zeros((32, 32), np.float32)
    coverage[20, 19] = 1.0  # the datum's cell searched: its four neighbours are equally likely
    south = np.array(ground(SEARCH_LOCATION, agent=(0.0, 109.375), coverage=coverage, datum=datum))
    north = np.array(ground(SEARCH_LOCATION, agent=(900.0, 109.375), coverage=coverage, datum=datum))
    np.testing.assert_allclose(south, cell_centre(19, 19))
    np.testing.assert_allclose(north, cell_centre(21, 19))
    # far from the datum, a near unlikely cell does not beat the likely ones: the prior still leads
    far = np.array(ground(SEARCH_LOCATION, agent=(-40.0, -490.0), coverage=coverage, datum=datum))
    assert np.hypot(*(far - datum)) < 100.0


def test_explore_prefers_the_nearest_unexplored_block_and_skips_explored_ones():
    agent = (0.0, 0.0)  # in block (0, 3)/(0, 4) boundary: cell row 1, col 16
    first = np.array(ground(EXPLORE, agent=agent))
    assert np.hypot(*(first - agent)) < 100.0  # a block next to the drone
    coverage = np.zeros((32, 32), np.float32)
    coverage[0:8, :] = 1.0  # the two southern block rows are explored
    second = np.array(ground(EXPLORE, agent=agent, coverage=coverage))
    assert second[0] > -50.0 + 8 * 31.25  # north of the explored band
    np.testing.assert_allclose(ground(EXPLORE, coverage=np.ones((32, 32), np.float32)), (600.0, 100.0))  # datum


def test_goals_are_grounded_independently_in_a_batch():
    goals = np.array([RETURN_TO_BASE, TRACK_OBJECT, SEARCH_LOCATION, EXPLORE])
    n = len(goals)
    points = ground_goals(goals, np.zeros((n, 2)), np.repeat(AREA, n, 0), np.zeros((n, 32, 32), np.float32),
                          np.tile([600.0, 100.0], (n, 1)), np.full(n, 80.0), np.tile([640.0, 80.0], (n, 1)),
                          np.array([False, True, False, False]), np.tile([5.0, -5.0], (n, 1)))
    np.testing.assert_allclose(points[0], (5.0, -5.0))
    np.testing.assert_allclose(points[1], (640.0, 80.0))
    for i, goal in ((2, SEARCH_LOCATION), (3, EXPLORE)):
        np.testing.assert_allclose(points[i], ground(goal))


# ---------------------------------------------------------------- routing around charted danger zones
ZONE = np.array([[[300.0, 0.0, 40.0]]])  # one zone of 40 m radius on the straight line north from home
VALID = np.array([[True]])


def route(agent, point, zones=ZONE, valid=VALID):
    return route_around_hazards(np.array([agent], float), np.array([point], float), zones, valid, AREA)[0]


def clearance(a, b, zone=ZONE[0, 0]) -> float:
    """Closest distance from the zone's centre to the segment a-b, minus its radius."""
    a, b, c = np.asarray(a, float), np.asarray(b, float), zone[:2]
    t = np.clip(np.dot(c - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)
    return float(np.hypot(*(a + t * (b - a) - c)) - zone[2])


def test_a_clear_leg_keeps_its_point():
    np.testing.assert_allclose(route((0.0, 0.0), (600.0, 200.0)), (600.0, 200.0))  # passes 75 m east of the zone
    np.testing.assert_allclose(route((0.0, 0.0), (600.0, 0.0), valid=np.array([[False]])), (600.0, 0.0))  # padding
    np.testing.assert_allclose(route((0.0, 0.0), (200.0, 0.0)), (200.0, 0.0))  # stops short of the zone


def test_a_leg_through_a_zone_goes_by_a_waypoint_clear_of_it_on_the_shorter_side():
    waypoint = route((0.0, 0.0), (600.0, 30.0))  # the point lies slightly east: pass on the east side
    assert waypoint[1] > 0.0
    assert clearance((0.0, 0.0), waypoint) >= HAZARD_MARGIN_M - 1e-6
    assert 0.0 < waypoint[0] < 600.0
    assert route((0.0, 0.0), (600.0, -30.0))[1] < 0.0  # and west for a point slightly west


def test_a_straight_flier_following_the_routed_points_reaches_the_point_and_never_enters_the_zone():
    for end in ((600.0, 0.0), (600.0, 10.0), (450.0, -5.0), (800.0, 60.0)):
        position, goal = np.zeros(2), np.array(end)
        for _ in range(200):
            waypoint = route(position, goal)
            while np.hypot(*(waypoint - position)) > 15.0:  # fly at 10 m/s until within reach, then ground again
                offset = waypoint - position
                step = offset / np.hypot(*offset) * min(10.0, np.hypot(*offset))
                assert clearance(position, position + step) > 5.0, (end, position)
                position = position + step
            if np.hypot(*(goal - position)) <= 15.0:
                break
        assert np.hypot(*(goal - position)) <= 15.0, end


def test_a_zone_by_the_fence_is_passed_on_the_side_away_from_it():
    from missions.goals import FENCE_MARGIN_M

    zone = np.array([[[300.0, 460.0, 40.0]]])  # 40 m from the east edge (500): no way round inside the margin there
    for start, end in (((0.0, 465.0), (600.0, 480.0)), ((0.0, 480.0), (600.0, 470.0)), ((600.0, 470.0), (0.0, 490.0))):
        waypoint = route(start, end, zones=zone)
        assert waypoint[1] < 460.0 - 40.0, (start, end, waypoint)  # west of the zone, where the shorter way is east
        assert clearance(start, waypoint, zone[0, 0]) >= HAZARD_MARGIN_M - 1e-6
        assert -500.0 + FENCE_MARGIN_M <= waypoint[1] <= 500.0 - FENCE_MARGIN_M
        assert -50.0 + FENCE_MARGIN_M <= waypoint[0] <= 950.0 - FENCE_MARGIN_M


def test_a_point_inside_a_zone_moves_to_its_rim_and_a_drone_inside_the_margin_leaves_it_first():
    rim = route((0.0, 0.0), (300.0, 10.0))  # inside the zone: onto the inflated rim, on the drone's side
    assert np.hypot(*(rim - ZONE[0, 0, :2])) >= 40.0 + HAZARD_MARGIN_M
    leave = route((300.0, -50.0), (300.0, 400.0))  # 10 m from the rim, the zone ahead: straight away first
    assert leave[1] < -50.0 and abs(leave[0] - 300.0) < 1e-6


def test_ground_goals_routes_every_goal_it_grounds():
    zones = np.repeat(np.array([[[300.0, 0.0, 40.0]]]), 2, axis=0)
    points = ground_goals(np.array([RETURN_TO_BASE, TRACK_OBJECT]), np.array([[600.0, 0.0], [0.0, 0.0]]),
                          np.repeat(AREA, 2, 0), np.zeros((2, 32, 32), np.float32), np.tile([600.0, 100.0], (2, 1)),
                          np.full(2, 80.0), np.array([[600.0, 100.0], [600.0, 0.0]]), np.array([False, True]),
                          np.zeros((2, 2)), zones, np.ones((2, 1), bool))
    # home, by a detour
    assert clearance((600.0, 0.0), points[0]) >= HAZARD_MARGIN_M - 1e-6 and 0.0 < points[0][0] < 600.0
    assert clearance((0.0, 0.0), points[1]) >= HAZARD_MARGIN_M - 1e-6 and 0.0 < points[1][0] < 600.0


def test_goal_points_stay_inside_the_area_by_the_fence_margin():
    from missions.goals import FENCE_MARGIN_M

    # a detection and a home right on the area's edges (AREA: north -50..950, east -500..500)
    points = ground_goals(np.array([TRACK_OBJECT, RETURN_TO_BASE]), np.zeros((2, 2)), np.repeat(AREA, 2, 0),
                          np.zeros((2, 32, 32), np.float32), np.tile([600.0, 100.0], (2, 1)), np.full(2, 80.0),
                          np.array([[950.0, -500.0], [0.0, 0.0]]), np.array([True, False]),
                          np.array([[0.0, 0.0], [-50.0, 500.0]]))
    np.testing.assert_allclose(points, [[950.0 - FENCE_MARGIN_M, -500.0 + FENCE_MARGIN_M],
                                        [-50.0 + FENCE_MARGIN_M, 500.0 - FENCE_MARGIN_M]])


# ---------------------------------------------------------------------------------------------- SarSearch-v1

def ground_v1(goal, agent=(0.0, 0.0), belief_cells=(((20, 19), 1.0),), searched=None, candidates=(), home=(0.0, 0.0),
              offset=(0.0, 0.0)):
    """SarSearch-v1's grounding with a belief that is zero but for ``belief_cells`` and candidates (point, kind)."""
    belief = np.zeros((1, 32, 32))
    for (row, col), value in belief_cells:
        belief[0, row, col] = value
    searched = np.zeros((1, 32, 32)) if searched is None else searched[None]
    points = np.zeros((1, 16, 2))
    kind = np.zeros((1, 16), dtype=np.int64)
    for k, (point, what) in enumerate(candidates):
        points[0, k], kind[0, k] = point, what
    return ground_goals_v1(np.array([goal]), np.array([agent], dtype=float), AREA, searched, belief,
                           np.array([offset]), points, kind, np.array([(600.0, 100.0)]), np.array([home]),
                           np.zeros((1, 1, 3)), np.zeros((1, 1), dtype=bool))[0]


def test_v1_search_location_is_the_most_belief_per_travel_where_its_water_is_now():
    np.testing.assert_allclose(ground_v1(SEARCH_LOCATION), cell_centre(20, 19))
    shifted = ground_v1(SEARCH_LOCATION, offset=(10.0, -5.0))
    np.testing.assert_allclose(shifted, np.array(cell_centre(20, 19)) + (10.0, -5.0))
    # two cells, the far one 1.5 times as likely: exp(-distance / 200 m) picks the near one 400 m closer
    cells = (((5, 16), 1.0), ((20, 16), 1.5))
    np.testing.assert_allclose(ground_v1(SEARCH_LOCATION, agent=cell_centre(5, 16), belief_cells=cells),
                               cell_centre(5, 16))
    assert TRAVEL_SCALE_M == 200.0 and 1.5 * np.exp(-(15 * 31.25) / 200.0) < 1.0


def test_v1_track_object_is_the_confirmed_victim_else_the_nearest_unresolved_candidate():
    near, far, victim = (100.0, 50.0), (400.0, -100.0), (700.0, 200.0)
    np.testing.assert_allclose(ground_v1(TRACK_OBJECT, candidates=[(far, 1), (near, 1)]), near)
    np.testing.assert_allclose(ground_v1(TRACK_OBJECT, candidates=[(near, 1), (victim, 2)]), victim)
    np.testing.assert_allclose(ground_v1(TRACK_OBJECT, candidates=[(near, 0)]), ground_v1(SEARCH_LOCATION))


def test_v1_explore_is_blind_to_the_belief_and_avoids_searched_blocks():
    searched = np.zeros((32, 32))
    searched[0:4, 16:20] = 1.0  # the block in front of home: searched
    point = ground_v1(EXPLORE, agent=(10.0, 10.0), searched=searched)
    assert not (-50.0 <= point[0] <= 75.0 and 0.0 <= point[1] <= 125.0)
    assert np.hypot(*point) < 200.0  # the nearest unsearched block, not the belief's peak 600 m away
