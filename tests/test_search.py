"""The search logic shared by training and flight: camera, detection, coverage, drift and end conditions."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from missions.coverage import GRID_SIZE, OBS_GRID, cover, downsample_coverage
from missions.generator import generate_scenario
from missions.mission import Mission
from missions.scenario import (CATEGORIES, Conditions, Obstacle, Scenario, SearchArea, SeaState, Target, TimeOfDay,
                               Weather)
from missions.search import (LEEWAY, SEA_FACTOR, SEA_FACTOR_BY_CATEGORY, ScenarioBatch, detected_categories,
                             detection_probability, distance_to_primary, drift_targets, footprint_half_width_m,
                             inside_obstacle, outside_fence, target_drift_velocity)

AREA = np.array([[-50.0, 950.0, -500.0, 500.0]])
PERSON, BOAT = CATEGORIES.index("person"), CATEGORIES.index("boat")


def p_single(target_ne=(0.0, 0.0), category=PERSON, altitude=20.0, zoom=0.0, intensity=1.0, sea=SeaState.CALM,
             weather=Weather.CLEAR, time_of_day=TimeOfDay.DAY, visibility=1.0, valid=True) -> float:
    """Detection probability of one target for a drone at the origin."""
    p = detection_probability(np.zeros((1, 2)), np.array([[target_ne]], dtype=float), np.array([[category]]),
                              np.array([[valid]]), np.array([altitude]), np.array([zoom]), np.array([intensity]),
                              np.array([int(sea)]), np.array([int(weather)]), np.array([int(time_of_day)]),
                              np.array([visibility]))
    assert p.shape == (1, 1)
    return float(p[0, 0])


# ------------------------------------------------------------------------------------------------ camera


def test_footprint_half_width():
    # 50 m * tan(35 deg) = 35.0104 m (the brief's "35.0 m" is this value rounded).
    assert footprint_half_width_m(50.0, 0.0) == pytest.approx(35.0104, abs=1e-4)
    assert footprint_half_width_m(50.0, 1.0) == pytest.approx(35.0104 / 4.0, abs=1e-4)
    h = footprint_half_width_m(np.array([10.0, 50.0, 120.0]), np.array([0.0, 0.5, 1.0]))
    np.testing.assert_allclose(h, np.array([10.0, 50.0 / 2.5, 120.0 / 4.0]) * math.tan(math.radians(35.0)))


# --------------------------------------------------------------------------------------------- detection


def test_detection_under_the_drone_in_good_conditions_is_high():
    assert p_single() >= 0.9
    # The formula, written out: 0.98 * (1 - exp(-0.5 * 1 * 150 / 20)).
    assert p_single() == pytest.approx(0.98 * (1 - math.exp(-3.75)))


@pytest.mark.parametrize("worse", [
    dict(weather=Weather.FOGGY), dict(weather=Weather.RAINY), dict(weather=Weather.CLOUDY),
    dict(time_of_day=TimeOfDay.NIGHT), dict(time_of_day=TimeOfDay.DUSK), dict(time_of_day=TimeOfDay.DAWN),
    dict(sea=SeaState.ROUGH), dict(sea=SeaState.MODERATE), dict(altitude=50.0), dict(visibility=0.5),
    dict(target_ne=(5.0, 3.0)), dict(intensity=0.6),
])
def test_detection_is_lower_in_worse_conditions(worse):
    assert 0.0 < p_single(**worse) < p_single()


def test_detection_off_centre_follows_the_range_factor():
    h = footprint_half_width_m(20.0, 0.0)
    r2 = 6.0 ** 2 + 8.0 ** 2
    assert p_single((6.0, 8.0)) == pytest.approx(p_single() * (1.0 - 0.5 * r2 / h ** 2))


def test_detection_is_zero_outside_the_footprint_and_for_padding():
    h = float(footprint_half_width_m(20.0, 0.0))
    assert p_single((0.0, h - 0.1)) > 0.0
    assert p_single((0.0, h + 0.1)) == 0.0
    assert p_single((-h - 0.1, 0.0)) == 0.0
    assert p_single((h - 0.1, h - 0.1)) >= 0.0  # corner of the square: range factor clipped at 0, not negative
    assert p_single(valid=False) == 0.0


def test_no_detection_with_the_sensor_off():
    assert p_single(intensity=0.0) == 0.0


def test_zoom_helps_a_small_object_at_altitude_but_shrinks_the_footprint():
    assert p_single(altitude=120.0, zoom=1.0) > p_single(altitude=120.0, zoom=0.0)
    assert footprint_half_width_m(120.0, 1.0) < footprint_half_width_m(120.0, 0.0)
    # At 120 m the half-width is 84 m at zoom 0 and 21 m at zoom 1: a target 25 m off in both axes drops out.
    assert p_single((25.0, 25.0), altitude=120.0, zoom=0.0) > 0.0
    assert p_single((25.0, 25.0), altitude=120.0, zoom=1.0) == 0.0


def test_boats_are_not_hidden_by_waves():
    np.testing.assert_allclose(SEA_FACTOR_BY_CATEGORY[:, BOAT], np.sqrt(SEA_FACTOR))
    np.testing.assert_allclose(SEA_FACTOR_BY_CATEGORY[:, PERSON], SEA_FACTOR)
    ratio_boat = p_single(category=BOAT, sea=SeaState.ROUGH) / p_single(category=BOAT)
    ratio_person = p_single(sea=SeaState.ROUGH) / p_single()
    assert ratio_boat == pytest.approx(math.sqrt(0.55)) and ratio_person == pytest.approx(0.55)


def test_detected_categories():
    detections = np.array([[True, False, True], [False, True, False]])
    category = np.array([[0, 1, 5], [2, 3, 3]])
    found = detected_categories(detections, category)
    np.testing.assert_array_equal(found, [[1, 0, 0, 0, 0, 1], [0, 0, 0, 1, 0, 0]])
    assert detected_categories(np.zeros((2, 3), bool), category).sum() == 0


# ---------------------------------------------------------------------------------------------- coverage


def reference_cover(coverage, area, drone_ne, half_width, intensity):
    """Cell by cell, straight from the definition (slow, for comparison)."""
    coverage = coverage.copy()
    for i in range(coverage.shape[0]):
        n_min, n_max, e_min, e_max = area[i]
        cell_n, cell_e = (n_max - n_min) / GRID_SIZE, (e_max - e_min) / GRID_SIZE
        if intensity[i] < 0.5:
            continue
        north, east = drone_ne[i]
        for r in range(GRID_SIZE):
            for c in range(GRID_SIZE):
                centre_n, centre_e = n_min + (r + 0.5) * cell_n, e_min + (c + 0.5) * cell_e
                if abs(centre_n - north) <= half_width[i] and abs(centre_e - east) <= half_width[i]:
                    coverage[i, r, c] = 1.0
        if n_min <= north <= n_max and e_min <= east <= e_max:
            r = min(int((north - n_min) // cell_n), GRID_SIZE - 1)
            c = min(int((east - e_min) // cell_e), GRID_SIZE - 1)
            coverage[i, r, c] = 1.0
    return coverage


@settings(max_examples=150, deadline=None)
@given(north=st.floats(-200, 1200), east=st.floats(-700, 700), altitude=st.floats(10, 400),
       zoom=st.floats(0, 1), size_e=st.sampled_from([1000.0, 300.0, 37.0]), on=st.booleans())
def test_cover_matches_the_definition(north, east, altitude, zoom, size_e, on):
    area = np.array([[-50.0, 950.0, -size_e / 2, size_e / 2]])
    drone = np.array([[north, east]])
    h = np.atleast_1d(footprint_half_width_m(altitude, zoom))
    intensity = np.array([1.0 if on else 0.2])
    coverage = np.zeros((1, GRID_SIZE, GRID_SIZE), np.float32)
    coverage[0, 3, 4] = 1.0  # something already covered
    expected = reference_cover(coverage, area, drone, h, intensity)
    newly = cover(coverage, area, drone, h, intensity)
    np.testing.assert_array_equal(coverage, expected)
    assert newly.tolist() == [int(expected.sum()) - 1]


def test_cover_over_a_random_flight():
    rng = np.random.default_rng(7)
    n = 6
    area = np.array([[-50.0, 950.0, -500.0, 500.0]] * 4 + [[0.0, 400.0, 0.0, 1000.0], [-10.0, 90.0, -10.0, 90.0]])
    coverage = np.zeros((n, GRID_SIZE, GRID_SIZE), np.float32)
    drone = np.array([[0.0, 0.0]] * 4 + [[200.0, 500.0], [40.0, 40.0]])
    for step in range(300):
        drone += rng.uniform(-30, 30, (n, 2))
        altitude = rng.uniform(10, 120, n)
        zoom = rng.uniform(0, 1, n)
        intensity = rng.uniform(0, 1, n)
        h = footprint_half_width_m(altitude, zoom)
        before = coverage.copy()
        expected = reference_cover(coverage, area, drone, h, intensity)
        newly = cover(coverage, area, drone, h, intensity)
        np.testing.assert_array_equal(coverage, expected)
        assert np.all(coverage >= before), "coverage never decreases"
        assert set(np.unique(coverage)) <= {0.0, 1.0}
        np.testing.assert_array_equal(newly, (coverage - before).sum(axis=(1, 2)))
        on_and_inside = (intensity >= 0.5) & ~outside_fence(drone, area)
        rows = np.floor((drone[:, 0] - area[:, 0]) * GRID_SIZE / (area[:, 1] - area[:, 0])).astype(int)
        cols = np.floor((drone[:, 1] - area[:, 2]) * GRID_SIZE / (area[:, 3] - area[:, 2])).astype(int)
        covered = coverage[np.arange(n), rows.clip(0, GRID_SIZE - 1), cols.clip(0, GRID_SIZE - 1)]
        assert np.all(covered[on_and_inside] == 1.0), "the drone's cell is covered"
    assert coverage.dtype == np.float32 and coverage.mean(axis=(1, 2)).max() > 0.05


def test_sensor_off_covers_nothing():
    coverage = np.zeros((2, GRID_SIZE, GRID_SIZE), np.float32)
    newly = cover(coverage, np.repeat(AREA, 2, axis=0), np.array([[100.0, 0.0], [400.0, 100.0]]),
                  np.array([80.0, 80.0]), np.array([0.0, 0.49]))
    assert coverage.sum() == 0.0 and newly.tolist() == [0, 0]


def test_cover_a_known_footprint():
    # Cells are 31.25 m; a drone at the centre of cell (10, 16) with h = 35 m sees rows 9-11 and columns 15-17.
    coverage = np.zeros((1, GRID_SIZE, GRID_SIZE), np.float32)
    north = -50.0 + 10.5 * 31.25
    newly = cover(coverage, AREA, np.array([[north, 15.625]]), np.array([35.0]), np.array([1.0]))
    expected = np.zeros((GRID_SIZE, GRID_SIZE), np.float32)
    expected[9:12, 15:18] = 1.0
    np.testing.assert_array_equal(coverage[0], expected)
    assert newly.tolist() == [9]
    assert coverage.mean(axis=(1, 2)).tolist() == [9 / 1024]
    # A footprint smaller than a cell still covers the drone's own cell.
    coverage[:] = 0.0
    cover(coverage, AREA, np.array([[north + 10.0, 15.625 + 12.0]]), np.array([2.0]), np.array([1.0]))
    assert coverage.sum() == 1.0 and coverage[0, 10, 16] == 1.0


def test_cover_rejects_a_non_contiguous_grid():
    coverage = np.zeros((1, GRID_SIZE, 2 * GRID_SIZE), np.float32)[:, :, :GRID_SIZE]
    with pytest.raises(ValueError, match="contiguous"):
        cover(coverage, AREA, np.zeros((1, 2)), np.array([35.0]), np.array([1.0]))


def test_downsample_is_the_2x2_mean_row_major():
    rng = np.random.default_rng(3)
    coverage = (rng.random((3, GRID_SIZE, GRID_SIZE)) < 0.4).astype(np.float32)
    blocks = downsample_coverage(coverage)
    assert blocks.shape == (3, OBS_GRID * OBS_GRID) and blocks.dtype == np.float32
    for n in range(3):
        for i in range(OBS_GRID):
            for j in range(OBS_GRID):
                block = coverage[n, 2 * i:2 * i + 2, 2 * j:2 * j + 2]
                assert blocks[n, i * OBS_GRID + j] == block.sum() / 4.0
    # A single covered cell in row 31 (north), column 0 (west) lands in block row 15, column 0.
    one = np.zeros((1, GRID_SIZE, GRID_SIZE), np.float32)
    one[0, 31, 0] = 1.0
    out = np.full((1, OBS_GRID * OBS_GRID), 7.0, np.float32)
    result = downsample_coverage(one, out=out)
    assert result is out or np.shares_memory(result, out)
    assert out[0, 15 * OBS_GRID] == 0.25 and out.sum() == 0.25


# ------------------------------------------------------------------------------------ drift and events


def test_drift_moves_targets_by_velocity_times_dt_exactly():
    rng = np.random.default_rng(1)
    targets = rng.uniform(-500, 500, (4, 3, 2))
    velocity = rng.uniform(-1, 1, (4, 3, 2))
    start = targets.copy()
    drift_targets(targets, velocity, 0.7)
    np.testing.assert_array_equal(targets, start + velocity * 0.7)


def test_drift_velocity_is_current_plus_leeway_times_wind():
    # Wind 1.0 = 15 m/s blowing towards the east; a person drifts with 3 % of it, plus a northward current.
    v = target_drift_velocity(np.array([PERSON, BOAT]), 1.0, 90.0, np.array([0.2, 0.0]))
    np.testing.assert_allclose(v, [[0.2, 15.0 * LEEWAY[PERSON]], [0.2, 15.0 * LEEWAY[BOAT]]], atol=1e-12)
    scenario = Scenario(targets=(Target("person", 100.0, 0.0, primary=True), Target("life_jacket", 0.0, 50.0)),
                        conditions=Conditions(wind=0.5, wind_direction_deg=180.0), current_east_mps=0.1)
    batch = ScenarioBatch.from_scenarios([scenario])
    np.testing.assert_allclose(batch.drift_velocity[0], [[-7.5 * 0.03, 0.1], [-7.5 * 0.05, 0.1]], atol=1e-12)


def test_reached_collision_and_boundary():
    drone = np.array([[0.0, 0.0], [100.0, 100.0], [949.0, 499.0], [951.0, 0.0], [0.0, -501.0]])
    targets = np.array([[[10.0, 10.0], [0.0, 0.0]], [[0.0, 0.0], [100.0, 115.1]], [[940.0, 490.0], [0.0, 0.0]],
                        [[0.0, 0.0], [0.0, 0.0]], [[0.0, 0.0], [0.0, 0.0]]])
    primary = np.array([0, 1, 0, 0, 1])
    np.testing.assert_allclose(distance_to_primary(drone, targets, primary),
                               [math.hypot(10, 10), 15.1, math.hypot(9, 9), 951.0, 501.0])
    obstacles = np.zeros((5, 2, 3))
    obstacles[0, 0] = (20.0, 0.0, 20.0)  # rim touches the drone: a collision
    obstacles[1, 1] = (100.0, 130.0, 29.0)  # 1 m short
    obstacles[2, 0] = (949.0, 499.0, 5.0)  # inside, but padding (invalid)
    obstacles[3, 1] = (900.0, 0.0, 60.0)  # inside
    valid = np.array([[True, False], [False, True], [False, False], [False, True], [True, True]])
    assert inside_obstacle(drone, obstacles, valid).tolist() == [True, False, False, True, False]
    fence = np.repeat(AREA, 5, axis=0)
    assert outside_fence(drone, fence).tolist() == [False, False, False, True, True]


# ------------------------------------------------------------------------------------------ the batch


def test_batch_equals_one_by_one():
    scenarios = [generate_scenario(seed) for seed in range(5)]
    assert len({len(s.targets) for s in scenarios}) > 1, "the check needs different padding"
    batch = ScenarioBatch.from_scenarios(scenarios)
    singles = [ScenarioBatch.from_scenarios([s]) for s in scenarios]
    rng = np.random.default_rng(11)
    n = len(scenarios)
    drone = batch.start.copy()
    targets = batch.targets.copy()
    single_targets = [s.targets.copy() for s in singles]
    coverage = np.zeros((n, GRID_SIZE, GRID_SIZE), np.float32)
    single_coverage = [np.zeros((1, GRID_SIZE, GRID_SIZE), np.float32) for _ in singles]
    for step in range(200):
        # Head for the primary target with noise, so that targets enter the footprint now and then.
        heading = targets[np.arange(n), batch.primary_index] - drone
        drone += 12.0 * heading / np.maximum(np.linalg.norm(heading, axis=1, keepdims=True), 1.0)
        drone += rng.normal(0.0, 3.0, (n, 2))
        altitude, zoom, intensity = rng.uniform(20, 120, n), rng.uniform(0, 1, n), rng.uniform(0, 1, n)
        h = footprint_half_width_m(altitude, zoom)
        p = batch.detection_probability(drone, targets, altitude, zoom, intensity)
        p_free = detection_probability(drone, targets, batch.target_category, batch.target_valid, altitude, zoom,
                                       intensity, batch.sea, batch.weather, batch.time_of_day, batch.visibility)
        np.testing.assert_array_equal(p, p_free)
        newly = cover(coverage, batch.area, drone, h, intensity)
        blocks = downsample_coverage(coverage)
        drift_targets(targets, batch.drift_velocity, 1.0)
        for i, single in enumerate(singles):
            t = single.targets.shape[1]
            p_i = single.detection_probability(drone[i:i + 1], single_targets[i], altitude[i:i + 1],
                                               zoom[i:i + 1], intensity[i:i + 1])
            np.testing.assert_allclose(p_i[0], p[i, :t], rtol=1e-12, atol=0)
            assert np.all(p[i, t:] == 0.0)
            assert cover(single_coverage[i], single.area, drone[i:i + 1], h[i:i + 1], intensity[i:i + 1])[0] \
                == newly[i]
            np.testing.assert_array_equal(single_coverage[i][0], coverage[i])
            np.testing.assert_array_equal(downsample_coverage(single_coverage[i])[0], blocks[i])
            drift_targets(single_targets[i], single.drift_velocity, 1.0)
            np.testing.assert_array_equal(single_targets[i][0], targets[i, :t])
    assert p.max() > 0.0, "some target was in view at some point"
    np.testing.assert_array_equal(
        distance_to_primary(drone, targets, batch.primary_index),
        [distance_to_primary(drone[i:i + 1], single_targets[i], s.primary_index)[0] for i, s in enumerate(singles)])
    np.testing.assert_array_equal(
        inside_obstacle(drone, batch.obstacles, batch.obstacle_valid),
        [inside_obstacle(drone[i:i + 1], s.obstacles, s.obstacle_valid)[0] for i, s in enumerate(singles)])


def test_batch_layout_select_and_assign():
    scenarios = [generate_scenario(seed) for seed in range(4)]
    batch = ScenarioBatch.from_scenarios(scenarios, num_targets=8, num_obstacles=5)
    assert batch.targets.shape == (4, 8, 2) and batch.obstacles.shape == (4, 5, 3) and len(batch) == 4
    for i, s in enumerate(scenarios):
        assert batch.target_valid[i].sum() == len(s.targets) and batch.obstacle_valid[i].sum() == len(s.obstacles)
        primary = batch.targets[i, batch.primary_index[i]]
        assert tuple(primary) == (s.primary.north_m, s.primary.east_m)
        assert CATEGORIES[batch.target_category[i, batch.primary_index[i]]] == s.primary.category
        assert batch.seeds[i] == s.seed and tuple(batch.area[i]) == (-50.0, 950.0, -500.0, 500.0)
    one = batch.select(2)
    assert len(one) == 1 and one.seeds.tolist() == [scenarios[2].seed]
    assert batch.select(-1).seeds.tolist() == [scenarios[3].seed]
    np.testing.assert_array_equal(one.detection_factor, batch.detection_factor[2:3])
    # Replace scenario 1 with a fresh one that has fewer slots: the rest becomes padding.
    fresh = ScenarioBatch.from_scenarios([generate_scenario(99)])
    batch.assign(1, fresh)
    reference = ScenarioBatch.from_scenarios([scenarios[0], generate_scenario(99), *scenarios[2:]],
                                             num_targets=8, num_obstacles=5)
    for name in ("targets", "target_valid", "target_category", "drift_velocity", "obstacles", "obstacle_valid",
                 "seeds", "detection_factor", "target_size_m", "area", "visibility"):
        np.testing.assert_array_equal(getattr(batch, name), getattr(reference, name))
    with pytest.raises(ValueError, match="num_targets"):
        ScenarioBatch.from_scenarios(scenarios, num_targets=1)


def test_mission_geofence_becomes_the_fence():
    scenario = Scenario()
    fence = SearchArea(-600.0, 600.0, -700.0, 700.0)
    missions = [Mission(scenario=scenario), Mission(scenario=scenario, geofence=fence)]
    batch = ScenarioBatch.from_scenarios([m.scenario for m in missions], [m.fence for m in missions])
    assert batch.fence.tolist() == [[-500.0, 500.0, -500.0, 500.0], [-600.0, 600.0, -700.0, 700.0]]
    drone = np.array([[550.0, 0.0], [550.0, 0.0]])
    assert outside_fence(drone, batch.fence).tolist() == [True, False]


def test_a_scenario_without_targets_or_obstacles():
    batch = ScenarioBatch.from_scenarios([Scenario(obstacles=(Obstacle(10.0, 10.0, 5.0),)), Scenario()])
    assert not batch.target_valid.any()
    assert not (distance_to_primary(batch.start, batch.targets, batch.primary_index) <= 100.0).any()
    assert batch.detection_probability(batch.start, batch.targets, 50.0, 0.0, 1.0).max() == 0.0
    assert inside_obstacle(np.array([[12.0, 12.0], [12.0, 12.0]]), batch.obstacles,
                           batch.obstacle_valid).tolist() == [True, False]


def test_single_scenario_cover_path_matches_the_batched_path():
    """cover() takes a slice-based path for N = 1; it must mark exactly what the batched path marks."""
    rng = np.random.default_rng(5)
    for _ in range(300):
        area = np.array([[-50.0, 950.0, -500.0, 500.0]])
        drone = rng.uniform([-120.0, -560.0], [1020.0, 560.0], size=(1, 2))
        half = np.array([rng.uniform(2.0, 90.0)])
        intensity = np.array([rng.uniform(0.0, 1.0)])
        start = (rng.uniform(size=(1, GRID_SIZE, GRID_SIZE)) < 0.2).astype(np.float32)
        single = start.copy()
        newly_single = cover(single, area, drone, half, intensity)
        pair = np.concatenate([start, start]).copy()
        newly_pair = cover(pair, np.repeat(area, 2, 0), np.repeat(drone, 2, 0), np.repeat(half, 2),
                           np.repeat(intensity, 2))
        np.testing.assert_array_equal(single[0], pair[0])
        assert newly_single[0] == newly_pair[0]
