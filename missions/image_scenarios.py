"""Search scenarios from annotated images: the image is a top-down view of the search area, its boxes the
targets and obstacles; what an image cannot show (sea, weather, current, the datum's error) is drawn from a
seeded generator."""
from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field

import numpy as np

from missions.geodesy import GeoPoint
from missions.scenario import Conditions, Obstacle, Scenario, SearchArea, SeaState, Target, TimeOfDay, Weather
from missions.validation import check_fields, check_number
from missions.yolo_labels import YoloItem


def image_seed(seed: int, split: str, index: int) -> int:
    """A per-image seed from the dataset seed, the split and the image's index in it."""
    return int(np.random.SeedSequence([seed, zlib.crc32(split.encode()), index]).generate_state(1)[0])


@dataclass(frozen=True)
class ImageScenarioConfig:
    """How an annotated image becomes a search scenario (the image is a top-down view of the search area)."""

    width_m: float = 1000.0
    """East-west extent of the area the image spans (m). Allowed [10, 100000]."""
    height_m: float | None = None
    """North-south extent (m); None keeps the image's aspect ratio (750 m for 640x480 images at 1,000 m),
    which needs the image size (read once per image). Allowed [10, 100000]."""
    south_margin_m: float = 50.0
    """How far home lies north of the area's southern edge (m): the area's north_min is -south_margin_m.
    Allowed [0, height]."""
    home: GeoPoint = field(default_factory=lambda: Scenario().home)
    """Geodetic home (origin of the local frame); the Scenario default."""
    min_obstacle_radius_m: float = 10.0
    """Smallest obstacle radius (m). Allowed [0.1, 10000]."""
    datum_sigma_m: tuple[float, float] = (50.0, 120.0)
    """Range of the datum uncertainty (m), drawn uniformly; the datum is the primary target's position plus
    an isotropic normal offset with that sigma. Allowed 0 <= low <= high <= 100000."""
    max_current_mps: float = 0.5
    """Sea currents are drawn with speeds uniform in [0, max_current_mps] (m/s). Allowed [0, 5]."""

    def __post_init__(self) -> None:
        # With the height left to the image, the margin is checked against it in area_for.
        height = (("height_m", 10.0, 1e5), ("south_margin_m", 0.0, self.height_m)) if self.height_m is not None \
            else (("south_margin_m", 0.0, 1e5),)
        check_fields(self, (("width_m", 10.0, 1e5), *height, ("min_obstacle_radius_m", 0.1, 1e4),
                            ("max_current_mps", 0.0, 5.0)))
        low, high = self.datum_sigma_m
        check_number("ImageScenarioConfig", "datum_sigma_m[0]", low, 0.0, 1e5)
        check_number("ImageScenarioConfig", "datum_sigma_m[1]", high, low, 1e5)

    def area_for(self, item: YoloItem) -> SearchArea:
        """The search area an image spans: centred east-west on home, south edge south_margin_m south of it."""
        height = self.height_m
        if height is None:
            width_px, height_px = item.image_size
            height = self.width_m * height_px / width_px
        if self.south_margin_m > height:
            raise ValueError(f"ImageScenarioConfig.south_margin_m ({self.south_margin_m:g}) must not exceed the "
                             f"area's height ({height:g} m)")
        return SearchArea(north_min_m=-self.south_margin_m, north_max_m=height - self.south_margin_m,
                          east_min_m=-self.width_m / 2, east_max_m=self.width_m / 2)


def image_to_local(area: SearchArea, x: float, y: float) -> tuple[float, float]:
    """Normalised image coordinates -> (north_m, east_m): x grows east, y grows downwards, i.e. south."""
    return area.north_max_m - y * area.size_north_m, area.east_min_m + x * area.size_east_m


# Visibility ranges (fraction) by weather: fog and rain shorten how far the camera sees.
_VISIBILITY = {Weather.CLEAR: (0.8, 1.0), Weather.CLOUDY: (0.6, 1.0), Weather.RAINY: (0.4, 0.8),
               Weather.FOGGY: (0.3, 0.6)}
# Wind ranges (fraction of full scale) by sea state, so that a rough sea comes with a strong wind.
_WIND = {SeaState.CALM: (0.0, 0.35), SeaState.MODERATE: (0.2, 0.7), SeaState.ROUGH: (0.5, 1.0)}


def _draw_conditions(rng: np.random.Generator) -> Conditions:
    # Sea, weather and time of day are drawn independently and uniformly: all 48 combinations occur.
    sea = SeaState(int(rng.integers(len(SeaState))))
    weather = Weather(int(rng.integers(len(Weather))))
    time_of_day = TimeOfDay(int(rng.integers(len(TimeOfDay))))
    visibility = float(rng.uniform(*_VISIBILITY[weather]))
    wind = float(rng.uniform(*_WIND[sea]))
    return Conditions(sea, weather, time_of_day, round(visibility, 3), round(wind, 3),
                      round(float(rng.uniform(0.0, 360.0)), 1))


def scenario_from_item(item: YoloItem, config: ImageScenarioConfig = ImageScenarioConfig(),
                       seed: int = 0) -> Scenario | None:
    """The search scenario an annotated image describes, or None when it has no primary candidate.

    The image spans ``config``'s area (x -> east, y downwards -> south); home and the start are at the
    middle of the southern part, ``south_margin_m`` north of the edge. Every target box becomes a Target at
    the box centre; the primary is :meth:`YoloItem.primary_box`. Obstacle boxes become obstacles whose radius
    is half the box diagonal in metres (at least ``min_obstacle_radius_m``); an obstacle that would cover
    the start point is left out, since the drone could not take off. Images carry no weather labels, so
    the conditions, the sea current and the datum offset are drawn from ``numpy.random.default_rng(seed)``.
    """
    primary = item.primary_box()
    if primary is None:
        return None
    area = config.area_for(item)
    rng = np.random.default_rng(seed)
    targets = tuple(Target(b.category, *image_to_local(area, b.cx, b.cy), primary=b is primary)
                    for b in item.targets)
    obstacles = []
    for box in item.obstacles:
        north, east = image_to_local(area, box.cx, box.cy)
        radius = max(config.min_obstacle_radius_m, 0.5 * math.hypot(box.w * area.size_east_m,
                                                                    box.h * area.size_north_m))
        if math.hypot(north, east) > radius:
            obstacles.append(Obstacle(north, east, radius))
    conditions = _draw_conditions(rng)
    speed, heading = rng.uniform(0.0, config.max_current_mps), rng.uniform(0.0, 2 * math.pi)
    sigma = float(rng.uniform(*config.datum_sigma_m))
    offset_north, offset_east = rng.normal(0.0, sigma, size=2) if sigma > 0 else (0.0, 0.0)
    primary_target = next(t for t in targets if t.primary)
    datum_north = float(np.clip(primary_target.north_m + offset_north, area.north_min_m, area.north_max_m))
    datum_east = float(np.clip(primary_target.east_m + offset_east, area.east_min_m, area.east_max_m))
    return Scenario(area=area, home=config.home, start_north_m=0.0, start_east_m=0.0,
                    datum_north_m=datum_north, datum_east_m=datum_east, datum_sigma_m=sigma,
                    targets=targets, obstacles=tuple(obstacles), conditions=conditions,
                    current_north_mps=float(speed * math.cos(heading)),
                    current_east_mps=float(speed * math.sin(heading)),
                    seed=int(seed), name=f"{item.split}/{item.stem}")
