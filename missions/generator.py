"""Seeded random search-and-rescue scenarios and the train / val / test splits.

``generate_scenario(seed)`` draws one :class:`~missions.scenario.Scenario` from a seeded
``numpy.random.Generator``: the same seed and config always give the same scenario.

What a generated scenario looks like (defaults of :class:`GeneratorConfig`):

* **Area.** 1,000 m x 1,000 m: north -50..950 m, east -500..500 m. Home (the origin of the local frame, and
  the start) sits in the middle of the southern edge, 50 m inside the area so that it is not on the fence.
* **Datum.** Uniform over the inner part of the area (100 m from every edge) and at least 250 m from home;
  ``datum_sigma_m`` uniform in [50, 120] m.
* **Targets.** The primary target (a person in the water, a swimmer, or their life jacket) is drawn around
  the datum with a normal distribution of that sigma per axis, clipped to stay 30 m inside the area; it
  comes first in ``Scenario.targets``. Then 0-5 distractors of any category, uniform over the area (30 m
  margin).
* **Obstacles.** 0-3 circles with radius 15-40 m, uniform over the area, redrawn (up to 100 times, then
  dropped) while their rim comes closer than 30 m to the start, the datum or the primary target.
* **Conditions.** Sea state, weather and time of day each uniform, so all 3 x 4 x 4 = 48 combinations are
  equally likely (1/48 each); visibility uniform in [0.3, 1.0], in [0.3, 0.6] in fog; wind ~ Beta(2, 5)
  (mostly light, mean 0.29 = 4.3 m/s), blowing towards a uniform direction; a current of 0-0.3 m/s
  (uniform) towards a uniform direction.

SarSearch-v1 (``TASK_V1``) adds, drawn after everything above so that the rest of a seed's scenario is its v0
scenario: decoys (objects of the victim's category around the datum), a sortie endurance and an error in the
current forecast.

Splits: seeds are disjoint integer ranges, ``SPLIT_SEED_STRIDE`` apart: train 0, 1, 2, ...; val
1,000,000,000 + i; test 2,000,000,000 + i. The first k seeds of a split are the same whatever count is asked
for, and a scenario's name tells where it came from: seed 2,000,000,017 is ``gen-test-000017``.
:func:`split_seed` maps any episode seed into a split (modulo the stride), for environments that draw
episode seeds freely.
The generator's random stream is keyed by (seed, ``GENERATOR_STREAM_TAG``), not by the seed alone, so it
never coincides with a runtime stream seeded with ``Scenario.seed`` (which is the generator seed).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from missions.scenario import (CATEGORIES, Conditions, Obstacle, Scenario, SearchArea, SeaState, Target, TimeOfDay,
                               Weather)
from missions.validation import Interval, check_fields

SPLITS: tuple[str, ...] = ("train", "val", "test", "test2")
"""train to learn on, val to choose settings, runs and policies on, test for the headlines; test2 a second test split
of scenarios no one has evaluated, kept to be opened once for one round's headline (docs/results.md)."""
SPLIT_SEED_STRIDE = 1_000_000_000
"""Seeds of split i are SPLIT_SEED_STRIDE * i + 0, 1, 2, ... (train 0, val 1, test 2, test2 3)."""
GENERATOR_STREAM_TAG = 0x5A12  # mixed into the generator's seed sequence: a stream of its own
_MAX_DRAWS = 10_000  # rejection-sampling cap for the datum (the config check makes success possible)
_OBSTACLE_DRAWS = 100  # attempts per obstacle before it is dropped


@dataclass(frozen=True)
class GeneratorConfig:
    """Parameters of the scenario distribution; the defaults are the project's standard distribution."""

    area_size_m: float = 1000.0
    """Side of the square search area (m). Allowed [200, 20000]."""
    home_inset_m: float = 50.0
    """How far north of the southern edge home / the start lies (m), centred east-west. Allowed [0, area/2]."""
    datum_margin_m: float = 100.0
    """The datum keeps at least this distance from every edge: the 'inner part' of the area (m).
    Allowed [0, area/2)."""
    min_datum_distance_m: float = 250.0
    """Least distance from home to the datum (m). Allowed [0, 1e5] and reachable inside the inner part."""
    datum_sigma_min_m: float = 50.0
    """Smallest datum uncertainty (1 sigma, m); datum_sigma_m is uniform in [min, max]. Allowed [1, 1000]."""
    datum_sigma_max_m: float = 120.0
    """Largest datum uncertainty (m). Allowed [datum_sigma_min_m, 1000]."""
    target_margin_m: float = 30.0
    """Targets stay at least this far inside the area (m). Allowed [0, area/2)."""
    primary_categories: tuple[str, ...] = ("person", "swimmer", "life_jacket")
    """Categories the primary target is drawn from (uniformly). Non-empty subset of CATEGORIES."""
    max_distractors: int = 5
    """Distractor objects: uniform count in [0, max]. Allowed [0, 50]."""
    max_obstacles: int = 3
    """Obstacles: uniform count in [0, max] (fewer when no clear place is found). Allowed [0, 20]."""
    obstacle_radius_min_m: float = 15.0
    """Smallest obstacle radius (m). Allowed [1, 500]."""
    obstacle_radius_max_m: float = 40.0
    """Largest obstacle radius (m). Allowed [obstacle_radius_min_m, 500]."""
    obstacle_clearance_m: float = 30.0
    """Least gap between an obstacle's rim and the start, the datum and the primary target (m).
    Allowed [0, 1000]."""
    visibility_min: float = 0.3
    """Lowest visibility (fraction). Allowed [0.3, 1]."""
    visibility_max: float = 1.0
    """Highest visibility (fraction). Allowed [visibility_min, 1]."""
    fog_visibility_max: float = 0.6
    """Highest visibility in fog. Allowed [visibility_min, 1]."""
    wind_beta_a: float = 2.0
    """Wind strength (fraction of WIND_FULL_SCALE_MPS) ~ Beta(a, b). Allowed (0, 100]."""
    wind_beta_b: float = 5.0
    """Second Beta parameter of the wind strength. Allowed (0, 100]."""
    max_current_mps: float = 0.3
    """Sea current speed is uniform in [0, max] (m/s). Allowed [0, 3]."""
    decoys_min: int = 0
    """Least number of decoys: objects of the victim's own category that are not the victim (other people's life
    jackets, a second swimmer, look-alike debris), which only a close look tells apart. Allowed [0, decoys_max]."""
    decoys_max: int = 0
    """Most decoys; the count is uniform in [decoys_min, decoys_max]. 0 = none (SarSearch-v0). Allowed [0, 20]."""
    decoy_spread_sigmas: float = 2.5
    """Decoys are drawn normally around the datum with this many datum sigmas per axis (a debris field around the
    incident), clipped inside the area and kept ``obstacle_clearance_m`` from danger zones. Allowed [0.1, 20]."""
    endurance_min_s: float = 0.0
    """Shortest sortie endurance (s); endurance_s is uniform in [min, max]. Allowed [0, endurance_max_s]."""
    endurance_max_s: float = 0.0
    """Longest sortie endurance (s); 0 = unlimited (SarSearch-v0). Allowed 0 or [60, 1e5]."""
    forecast_error_mps: float = 0.0
    """1-sigma error of the crew's current forecast, per axis (m/s): the datum and the belief drift with the
    forecast, the objects with the true current. 0 = an exact forecast (SarSearch-v0). Allowed [0, 1]."""

    def __post_init__(self) -> None:
        half = self.area_size_m / 2.0 if isinstance(self.area_size_m, (int, float)) else math.nan
        inner = Interval(0.0, half, high_open=True)  # a margin of half the area would leave no inner part
        beta = Interval(0.0, 100.0, low_open=True)  # Beta distribution parameters are strictly positive
        check_fields(self, (
            ("area_size_m", 200.0, 20000.0), ("home_inset_m", 0.0, half), ("datum_margin_m", inner),
            ("min_datum_distance_m", 0.0, 1e5), ("datum_sigma_min_m", 1.0, 1000.0),
            ("datum_sigma_max_m", self.datum_sigma_min_m, 1000.0), ("target_margin_m", inner),
            ("max_distractors", 0, 50), ("max_obstacles", 0, 20), ("obstacle_radius_min_m", 1.0, 500.0),
            ("obstacle_radius_max_m", self.obstacle_radius_min_m, 500.0), ("obstacle_clearance_m", 0.0, 1000.0),
            ("visibility_min", 0.3, 1.0), ("visibility_max", self.visibility_min, 1.0),
            ("fog_visibility_max", self.visibility_min, 1.0), ("wind_beta_a", beta), ("wind_beta_b", beta),
            ("max_current_mps", 0.0, 3.0), ("decoys_max", 0, 20), ("decoys_min", 0, self.decoys_max),
            ("decoy_spread_sigmas", 0.1, 20.0), ("endurance_max_s", 0.0, 1e5),
            ("endurance_min_s", 0.0, self.endurance_max_s), ("forecast_error_mps", 0.0, 1.0),
        ), integers=("max_distractors", "max_obstacles", "decoys_max", "decoys_min"))
        if 0.0 < self.endurance_max_s < 60.0:
            raise ValueError(f"GeneratorConfig.endurance_max_s must be 0 (unlimited) or in [60, 100000], "
                             f"got {self.endurance_max_s!r}")
        if not self.primary_categories or any(c not in CATEGORIES for c in self.primary_categories):
            raise ValueError(f"GeneratorConfig.primary_categories must be a non-empty subset of "
                             f"{', '.join(CATEGORIES)}, got {self.primary_categories!r}")
        # The farthest point of the inner part from home must be far enough, or no datum can ever be drawn.
        area = self.area()
        farthest = math.hypot(max(abs(area.north_min_m + self.datum_margin_m), area.north_max_m - self.datum_margin_m),
                              area.east_max_m - self.datum_margin_m)
        if self.min_datum_distance_m >= farthest:
            raise ValueError(f"GeneratorConfig.min_datum_distance_m must be below {farthest:g} m (the farthest point "
                             f"of the inner part of the area from home), got {self.min_datum_distance_m!r}")

    def area(self) -> SearchArea:
        """The search area in the local frame of home (home at north 0, east 0)."""
        return SearchArea(north_min_m=-self.home_inset_m, north_max_m=self.area_size_m - self.home_inset_m,
                          east_min_m=-self.area_size_m / 2.0, east_max_m=self.area_size_m / 2.0)


TASK_V1 = GeneratorConfig(decoys_min=1, decoys_max=4, endurance_min_s=600.0, endurance_max_s=900.0,
                          forecast_error_mps=0.05)
"""The scenario distribution of SarSearch-v1: the standard one plus 1-4 decoys around the datum, a sortie
endurance of 600-900 s and a current forecast off by 0.05 m/s per axis (1 sigma); see docs/environment.md."""


def scenario_seeds(split: str, count: int) -> list[int]:
    """The first ``count`` generator seeds of ``split`` (one of ``SPLITS``); splits never overlap."""
    if split not in SPLITS:
        raise ValueError(f"split must be one of {', '.join(SPLITS)}, got {split!r}")
    if isinstance(count, bool) or not isinstance(count, int) or not 0 <= count <= SPLIT_SEED_STRIDE:
        raise ValueError(f"count must be an integer in [0, {SPLIT_SEED_STRIDE}], got {count!r}")
    first = SPLITS.index(split) * SPLIT_SEED_STRIDE
    return list(range(first, first + count))


def split_seed(split: str, index: int) -> int:
    """Generator seed of scenario ``index`` of ``split``: ``scenario_seeds(split, index + 1)[index]``.

    Any non-negative index is accepted and taken modulo SPLIT_SEED_STRIDE, so that an arbitrary episode seed
    (a 63-bit hash, say) still names a scenario of that split and of no other.
    """
    if split not in SPLITS:
        raise ValueError(f"split must be one of {', '.join(SPLITS)}, got {split!r}")
    if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or index < 0:
        raise ValueError(f"index must be a non-negative integer, got {index!r}")
    return SPLITS.index(split) * SPLIT_SEED_STRIDE + int(index) % SPLIT_SEED_STRIDE


def scenario_name(seed: int) -> str:
    """'gen-<split>-<index>' for split seeds (e.g. 'gen-test-000017'), 'gen-seed-<seed>' beyond them."""
    split, index = divmod(seed, SPLIT_SEED_STRIDE)
    if split < len(SPLITS):
        return f"gen-{SPLITS[split]}-{index:06d}"
    return f"gen-seed-{seed}"


def generate_scenario(seed: int, config: GeneratorConfig = GeneratorConfig()) -> Scenario:
    """Draw one scenario; the same (seed, config) always gives the same scenario."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    seed = int(seed)
    rng = np.random.default_rng([seed, GENERATOR_STREAM_TAG])
    area = config.area()
    start = (0.0, 0.0)  # home; the local frame's origin

    datum = _draw_datum(rng, area, config)
    sigma = float(rng.uniform(config.datum_sigma_min_m, config.datum_sigma_max_m))
    margin = config.target_margin_m
    north = float(np.clip(datum[0] + sigma * rng.standard_normal(), area.north_min_m + margin,
                          area.north_max_m - margin))
    east = float(np.clip(datum[1] + sigma * rng.standard_normal(), area.east_min_m + margin,
                         area.east_max_m - margin))
    primary_category = config.primary_categories[int(rng.integers(len(config.primary_categories)))]
    targets = [Target(primary_category, north, east, primary=True)]
    for _ in range(int(rng.integers(config.max_distractors + 1))):
        category = CATEGORIES[int(rng.integers(len(CATEGORIES)))]
        targets.append(Target(category, *_uniform_point(rng, area, margin)))

    keep_clear = np.array([start, datum, (north, east)])
    obstacles = []
    for _ in range(int(rng.integers(config.max_obstacles + 1))):
        obstacle = _draw_obstacle(rng, area, keep_clear, config)
        if obstacle is not None:
            obstacles.append(obstacle)

    conditions, current = _draw_conditions(rng, config), _draw_current(rng, config)
    # SarSearch-v1's draws come last, so that a config without them gives exactly the v0 scenario of the seed.
    targets += _draw_decoys(rng, area, datum, sigma, primary_category, obstacles, config)
    endurance = (float(rng.uniform(config.endurance_min_s, config.endurance_max_s))
                 if config.endurance_max_s > 0.0 else None)
    forecast = {}
    if config.forecast_error_mps > 0.0:
        error = config.forecast_error_mps * rng.standard_normal(2)
        forecast = {"forecast_current_north_mps": current["current_north_mps"] + float(error[0]),
                    "forecast_current_east_mps": current["current_east_mps"] + float(error[1])}
    return Scenario(
        area=area, start_north_m=start[0], start_east_m=start[1],
        datum_north_m=datum[0], datum_east_m=datum[1], datum_sigma_m=sigma,
        targets=tuple(targets), obstacles=tuple(obstacles), conditions=conditions,
        **current, **forecast, endurance_s=endurance, seed=seed, name=scenario_name(seed),
    )


def _draw_decoys(rng: np.random.Generator, area: SearchArea, datum: tuple[float, float], sigma: float,
                 category: str, obstacles: list[Obstacle], config: GeneratorConfig) -> list[Target]:
    """Objects of the victim's category around the datum, away from the danger zones (a close look must be able
    to reach them); a decoy with no clear place in ``_OBSTACLE_DRAWS`` draws is dropped."""
    if config.decoys_max == 0:
        return []
    margin, spread = config.target_margin_m, config.decoy_spread_sigmas * sigma
    zones = np.array([(o.north_m, o.east_m, o.radius_m) for o in obstacles]).reshape(-1, 3)
    decoys = []
    for _ in range(int(rng.integers(config.decoys_min, config.decoys_max + 1))):
        for _ in range(_OBSTACLE_DRAWS):
            north = float(np.clip(datum[0] + spread * rng.standard_normal(), area.north_min_m + margin,
                                  area.north_max_m - margin))
            east = float(np.clip(datum[1] + spread * rng.standard_normal(), area.east_min_m + margin,
                                 area.east_max_m - margin))
            gaps = np.hypot(zones[:, 0] - north, zones[:, 1] - east) - zones[:, 2]
            if len(gaps) == 0 or gaps.min() >= config.obstacle_clearance_m:
                decoys.append(Target(category, north, east))
                break
    return decoys


def _uniform_point(rng: np.random.Generator, area: SearchArea, margin: float) -> tuple[float, float]:
    return (float(rng.uniform(area.north_min_m + margin, area.north_max_m - margin)),
            float(rng.uniform(area.east_min_m + margin, area.east_max_m - margin)))


def _draw_datum(rng: np.random.Generator, area: SearchArea, config: GeneratorConfig) -> tuple[float, float]:
    # Rejection sampling keeps the datum uniform over the inner part minus the disc around home.
    for _ in range(_MAX_DRAWS):
        north, east = _uniform_point(rng, area, config.datum_margin_m)
        if math.hypot(north, east) >= config.min_datum_distance_m:
            return north, east
    raise RuntimeError(f"no datum found in {_MAX_DRAWS} draws; lower GeneratorConfig.min_datum_distance_m")


def _draw_obstacle(rng: np.random.Generator, area: SearchArea, keep_clear: np.ndarray,
                   config: GeneratorConfig) -> Obstacle | None:
    for _ in range(_OBSTACLE_DRAWS):
        radius = float(rng.uniform(config.obstacle_radius_min_m, config.obstacle_radius_max_m))
        north, east = _uniform_point(rng, area, 0.0)
        gaps = np.hypot(keep_clear[:, 0] - north, keep_clear[:, 1] - east) - radius
        if gaps.min() >= config.obstacle_clearance_m:
            return Obstacle(north, east, radius)
    return None  # the area is too crowded for this one; the scenario gets one obstacle fewer


def _draw_conditions(rng: np.random.Generator, config: GeneratorConfig) -> Conditions:
    sea = SeaState(int(rng.integers(len(SeaState))))
    weather = Weather(int(rng.integers(len(Weather))))
    time_of_day = TimeOfDay(int(rng.integers(len(TimeOfDay))))
    top = min(config.visibility_max, config.fog_visibility_max) if weather == Weather.FOGGY else config.visibility_max
    return Conditions(sea=sea, weather=weather, time_of_day=time_of_day,
                      visibility=float(rng.uniform(config.visibility_min, top)),
                      wind=float(rng.beta(config.wind_beta_a, config.wind_beta_b)),
                      wind_direction_deg=float(rng.uniform(0.0, 360.0)))


def _draw_current(rng: np.random.Generator, config: GeneratorConfig) -> dict[str, float]:
    speed = float(rng.uniform(0.0, config.max_current_mps))
    direction = math.radians(float(rng.uniform(0.0, 360.0)))
    return {"current_north_mps": speed * math.cos(direction), "current_east_mps": speed * math.sin(direction)}
