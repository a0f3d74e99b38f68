"""The scenario generator: determinism, splits, the shape of the distribution, config validation."""
from __future__ import annotations

import math

import numpy as np
import pytest

from missions.generator import (SPLIT_SEED_STRIDE, SPLITS, TASK_V1, GeneratorConfig, generate_scenario,
                                scenario_name, scenario_seeds, split_seed)
from missions.scenario import Weather


@pytest.fixture(scope="module")
def many():
    """2,000 training scenarios (about a quarter of a second)."""
    return [generate_scenario(seed) for seed in scenario_seeds("train", 2000)]


def test_same_seed_same_scenario_and_different_seeds_differ():
    assert generate_scenario(12345) == generate_scenario(12345)
    assert generate_scenario(12345) != generate_scenario(12346)
    config = GeneratorConfig(area_size_m=600.0, min_datum_distance_m=150.0, max_obstacles=6)
    assert generate_scenario(7, config) == generate_scenario(7, config)
    assert generate_scenario(7, config) != generate_scenario(7)
    scenarios = [generate_scenario(seed) for seed in scenario_seeds("val", 50)]
    datums = {(s.datum_north_m, s.datum_east_m) for s in scenarios}
    assert len(datums) == 50


def test_splits_are_disjoint_and_stable():
    seeds = {split: set(scenario_seeds(split, 5000)) for split in SPLITS}
    assert sum(len(s) for s in seeds.values()) == len(set().union(*seeds.values())) == 5000 * len(SPLITS)
    assert scenario_seeds("test", 10) == scenario_seeds("test", 20)[:10]  # growing a split keeps its prefix
    assert scenario_seeds("test", 18)[17] == 2 * SPLIT_SEED_STRIDE + 17
    scenario = [generate_scenario(seed) for seed in scenario_seeds("test", 18)][17]
    assert scenario.name == "gen-test-000017" and scenario.seed == 2 * SPLIT_SEED_STRIDE + 17
    assert scenario_name(5) == "gen-train-000005" and scenario_name(3 * SPLIT_SEED_STRIDE + 4) == "gen-test2-000004"
    assert scenario_name(4 * SPLIT_SEED_STRIDE) == "gen-seed-4000000000"
    assert [split_seed("val", i) for i in range(30)] == scenario_seeds("val", 30)
    for episode_seed in (0, 17, SPLIT_SEED_STRIDE + 5, 2**63 - 1, np.uint64(2**64 - 1)):
        seeds = {split: split_seed(split, episode_seed) for split in SPLITS}
        for i, split in enumerate(SPLITS):  # a free episode seed still lands in its split's range
            assert i * SPLIT_SEED_STRIDE <= seeds[split] < (i + 1) * SPLIT_SEED_STRIDE
    with pytest.raises(ValueError, match="split"):
        split_seed("holdout", 3)
    with pytest.raises(ValueError, match="index"):
        split_seed("train", -3)
    with pytest.raises(ValueError, match="split"):
        scenario_seeds("holdout", 3)
    with pytest.raises(ValueError, match="count"):
        scenario_seeds("train", -1)
    with pytest.raises(ValueError, match="seed"):
        generate_scenario(-4)


def test_all_48_condition_combinations_appear(many):
    combos = {(s.conditions.sea, s.conditions.weather, s.conditions.time_of_day) for s in many}
    assert len(combos) == 48


def test_layout_of_generated_scenarios(many):
    for s in many:
        area = s.area
        assert (area.north_min_m, area.north_max_m, area.east_min_m, area.east_max_m) == (-50.0, 950.0, -500.0, 500.0)
        assert (s.start_north_m, s.start_east_m) == (0.0, 0.0) and area.contains(0.0, 0.0)
        assert math.hypot(s.datum_north_m, s.datum_east_m) >= 250.0
        assert -50.0 + 100.0 <= s.datum_north_m <= 950.0 - 100.0 and abs(s.datum_east_m) <= 400.0
        assert 50.0 <= s.datum_sigma_m <= 120.0
        primary = s.primary
        assert s.targets[0] is primary and sum(t.primary for t in s.targets) == 1
        assert primary.category in ("person", "swimmer", "life_jacket")
        assert -20.0 <= primary.north_m <= 920.0 and abs(primary.east_m) <= 470.0  # 30 m inside the area
        assert 0 <= len(s.targets) - 1 <= 5 and len(s.obstacles) <= 3
        for t in s.targets:
            assert area.contains(t.north_m, t.east_m)
        assert 0.3 <= s.conditions.visibility <= 1.0 and 0.0 <= s.conditions.wind <= 1.0
        if s.conditions.weather == Weather.FOGGY:
            assert s.conditions.visibility <= 0.6
        assert math.hypot(s.current_north_mps, s.current_east_mps) <= 0.3 + 1e-12
        assert s.name.startswith("gen-train-")


def test_obstacles_never_cover_start_datum_or_primary(many):
    counted = 0
    for s in many:
        keep_clear = [(s.start_north_m, s.start_east_m), (s.datum_north_m, s.datum_east_m),
                      (s.primary.north_m, s.primary.east_m)]
        for o in s.obstacles:
            assert 15.0 <= o.radius_m <= 40.0
            for north, east in keep_clear:
                assert math.hypot(north - o.north_m, east - o.east_m) >= o.radius_m + 30.0
            counted += 1
    assert counted > 2000  # about 1.5 per scenario: the check is not vacuous


def test_distribution_is_roughly_as_documented(many):
    # Loose bounds (many standard errors wide): they catch a wrong distribution, not noise.
    wind = np.array([s.conditions.wind for s in many])
    assert 0.25 < wind.mean() < 0.33  # Beta(2, 5) has mean 2/7 = 0.286
    primary_kinds = {s.primary.category for s in many}
    assert primary_kinds == {"person", "swimmer", "life_jacket"}
    distractor_kinds = {t.category for s in many for t in s.targets[1:]}
    assert len(distractor_kinds) == 6
    offsets = np.array([(s.primary.north_m - s.datum_north_m) / s.datum_sigma_m for s in many])
    assert 0.85 < offsets.std() < 1.1  # about one sigma (clipping at the edges trims a little)


@pytest.mark.parametrize("field, value", [
    ("area_size_m", 50.0), ("area_size_m", float("nan")), ("home_inset_m", -1.0), ("datum_margin_m", 500.0),
    ("datum_sigma_min_m", 0.0), ("datum_sigma_max_m", 10.0), ("target_margin_m", -5.0), ("max_distractors", 2.5),
    ("max_distractors", -1), ("max_obstacles", 21), ("obstacle_radius_max_m", 5.0), ("visibility_min", 0.1),
    ("visibility_max", 1.2), ("fog_visibility_max", 0.2), ("wind_beta_a", 0.0), ("max_current_mps", 4.0),
    ("min_datum_distance_m", 2000.0), ("primary_categories", ()), ("primary_categories", ("kayak",)),
    ("decoys_max", 21), ("decoys_min", 3), ("decoy_spread_sigmas", 0.0), ("endurance_max_s", 30.0),
    ("endurance_min_s", 10.0), ("forecast_error_mps", 2.0),
])
def test_config_validation_names_the_field(field, value):
    with pytest.raises(ValueError, match=f"GeneratorConfig.{field}"):
        GeneratorConfig(**{field: value})


def test_a_custom_config_is_respected():
    config = GeneratorConfig(area_size_m=400.0, home_inset_m=0.0, datum_margin_m=50.0, min_datum_distance_m=100.0,
                             datum_sigma_min_m=10.0, datum_sigma_max_m=20.0, max_distractors=0, max_obstacles=0,
                             primary_categories=("swimmer",))
    for seed in range(200):
        s = generate_scenario(seed, config)
        assert s.area.north_min_m == 0.0 and s.area.north_max_m == 400.0 and s.area.east_max_m == 200.0
        assert len(s.targets) == 1 and s.primary.category == "swimmer" and not s.obstacles
        assert 10.0 <= s.datum_sigma_m <= 20.0 and math.hypot(s.datum_north_m, s.datum_east_m) >= 100.0


def test_sarsearch_v1_adds_decoys_an_endurance_and_a_forecast_error_to_the_v0_scenario():
    decoys, endurance, errors, spreads = [], [], [], []
    for seed in range(300):
        v0, v1 = generate_scenario(seed), generate_scenario(seed, TASK_V1)
        assert v1.targets[:len(v0.targets)] == v0.targets and v1.obstacles == v0.obstacles  # the rest is v0's
        assert (v1.conditions, v1.datum_north_m, v1.current_north_mps) == (v0.conditions, v0.datum_north_m,
                                                                         v0.current_north_mps)
        extra = v1.targets[len(v0.targets):]
        assert all(t.category == v1.primary.category and not t.primary for t in extra)  # look-alikes of the victim
        decoys.append(len(extra))
        spreads += [math.hypot(t.north_m - v1.datum_north_m, t.east_m - v1.datum_east_m) / v1.datum_sigma_m
                    for t in extra]
        endurance.append(v1.endurance_s)
        errors.append(v1.forecast_current_north_mps - v1.current_north_mps)
        for t in extra:  # clear of the danger zones, as a close look must reach them
            assert all(math.hypot(t.north_m - o.north_m, t.east_m - o.east_m) - o.radius_m >= 30.0
                       for o in v1.obstacles)
        assert v0.endurance_s is None and v0.forecast_current_north_mps is None
    assert set(decoys) <= {1, 2, 3, 4} and min(decoys) == 1 and max(decoys) == 4
    assert 600.0 <= min(endurance) and max(endurance) <= 900.0
    assert abs(np.std(errors) - 0.05) < 0.01
    assert 1.5 < np.median(spreads) < 4.5  # normal with 2.5 sigmas per axis: a median radius of about 2.9 sigmas
