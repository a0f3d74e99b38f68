"""Search-and-rescue scenarios: where to search, what is out there, and in which conditions.

A :class:`Scenario` is plain data (frozen dataclasses, metres in the local NED frame of ``home``), shared by
the training environment, the mission files, the datasets and the flight runtime. Positions are
(north_m, east_m) relative to home; the search area is an axis-aligned rectangle in that frame.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass, field

from missions.geodesy import GeoPoint
from missions.validation import check_number

# The paper's six object categories, in the order of the observation's detection binaries.
CATEGORIES: tuple[str, ...] = ("person", "boat", "life_jacket", "debris", "floating_object", "swimmer")


class SeaState(enum.IntEnum):
    CALM = 0
    MODERATE = 1
    ROUGH = 2


class Weather(enum.IntEnum):
    CLEAR = 0
    CLOUDY = 1
    FOGGY = 2
    RAINY = 3


class TimeOfDay(enum.IntEnum):
    DAWN = 0
    DAY = 1
    DUSK = 2
    NIGHT = 3


@dataclass(frozen=True)
class Conditions:
    """Environmental conditions; all 3 x 4 x 4 = 48 sea/weather/time combinations are allowed."""

    sea: SeaState = SeaState.CALM
    """Sea state: calm, moderate or rough (rough hides small objects in the waves)."""
    weather: Weather = Weather.CLEAR
    """Clear, cloudy, foggy or rainy."""
    time_of_day: TimeOfDay = TimeOfDay.DAY
    """Dawn, day, dusk or night (light level)."""
    visibility: float = 1.0
    """Meteorological visibility as a fraction, in [0.3, 1.0]."""
    wind: float = 0.0
    """Wind strength as a fraction of WIND_FULL_SCALE_MPS, in [0, 1]."""
    wind_direction_deg: float = 0.0
    """Direction the wind blows TOWARDS, degrees clockwise from north (drift direction)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "sea", SeaState(self.sea))
        object.__setattr__(self, "weather", Weather(self.weather))
        object.__setattr__(self, "time_of_day", TimeOfDay(self.time_of_day))
        check_number("Conditions", "visibility", self.visibility, 0.3, 1.0)
        check_number("Conditions", "wind", self.wind, 0.0, 1.0)
        check_number("Conditions", "wind_direction_deg", self.wind_direction_deg, -360.0, 360.0)


WIND_FULL_SCALE_MPS = 15.0  # Conditions.wind = 1 means a 15 m/s (about 30 kn, Beaufort 7) wind


@dataclass(frozen=True)
class Target:
    """An object in the water. Exactly one target of a scenario is the primary one (the victim to reach)."""

    category: str
    """One of CATEGORIES."""
    north_m: float
    east_m: float
    primary: bool = False

    def __post_init__(self) -> None:
        if self.category not in CATEGORIES:
            raise ValueError(f"Target.category must be one of {', '.join(CATEGORIES)}, got {self.category!r}")
        check_number("Target", "north_m", self.north_m, -1e6, 1e6)
        check_number("Target", "east_m", self.east_m, -1e6, 1e6)


@dataclass(frozen=True)
class Obstacle:
    """A circular danger zone (vessel, rocks, wind turbine, restricted area) the drone must not enter."""

    north_m: float
    east_m: float
    radius_m: float

    def __post_init__(self) -> None:
        check_number("Obstacle", "radius_m", self.radius_m, 0.1, 1e5)


@dataclass(frozen=True)
class SearchArea:
    """Axis-aligned rectangle in the local NED frame of home (metres)."""

    north_min_m: float = -500.0
    north_max_m: float = 500.0
    east_min_m: float = -500.0
    east_max_m: float = 500.0

    def __post_init__(self) -> None:
        if not (self.north_max_m - self.north_min_m >= 10.0 and self.east_max_m - self.east_min_m >= 10.0):
            raise ValueError("SearchArea: north_max_m - north_min_m and east_max_m - east_min_m must be >= 10 m, "
                             f"got {self.north_max_m - self.north_min_m:g} x {self.east_max_m - self.east_min_m:g}")

    @property
    def size_north_m(self) -> float:
        return self.north_max_m - self.north_min_m

    @property
    def size_east_m(self) -> float:
        return self.east_max_m - self.east_min_m

    def contains(self, north_m: float, east_m: float) -> bool:
        return self.north_min_m <= north_m <= self.north_max_m and self.east_min_m <= east_m <= self.east_max_m


@dataclass(frozen=True)
class Scenario:
    """One search problem: area, base, last known position, objects, hazards, conditions and drift."""

    area: SearchArea = field(default_factory=SearchArea)
    """The search area (also the geofence of the training environment)."""
    home: GeoPoint = field(default_factory=lambda: GeoPoint(47.397742, 8.545594, 488.0))
    """Geodetic base / launch point: the origin of the local frame."""
    start_north_m: float = 0.0
    """Where the drone starts searching (local frame); normally home."""
    start_east_m: float = 0.0
    datum_north_m: float = 0.0
    """Datum: the last known position of the victim (local frame)."""
    datum_east_m: float = 0.0
    datum_sigma_m: float = 100.0
    """1-sigma uncertainty of the datum (m): how far from it the victim may be."""
    targets: tuple[Target, ...] = ()
    """Objects in the water; exactly one is primary."""
    obstacles: tuple[Obstacle, ...] = ()
    conditions: Conditions = field(default_factory=Conditions)
    current_north_mps: float = 0.0
    """Sea current (m/s); objects drift with the current plus a leeway share of the wind."""
    current_east_mps: float = 0.0
    forecast_current_north_mps: float | None = None
    """The current the crew's drift forecast assumes (m/s); None = the true current (an exact forecast, as in
    SarSearch-v0). The datum and the search belief drift with the forecast, the objects with the truth."""
    forecast_current_east_mps: float | None = None
    """East part of the forecast current (m/s); None = the true current."""
    endurance_s: float | None = None
    """Flight time the drone's battery allows for this sortie, counted from the start of the search (s); the
    search must leave enough of it to fly home. None = unlimited (SarSearch-v0)."""
    seed: int = 0
    """Seed of everything random while this scenario is flown (detections)."""
    name: str = ""
    """Where the scenario came from (generator seed, dataset image)."""

    def __post_init__(self) -> None:
        primaries = sum(1 for t in self.targets if t.primary)
        if self.targets and primaries != 1:
            raise ValueError(f"Scenario.targets must contain exactly one primary target, got {primaries}")
        check_number("Scenario", "datum_sigma_m", self.datum_sigma_m, 0.0, 1e5)
        check_number("Scenario", "current_north_mps", self.current_north_mps, -5.0, 5.0)
        check_number("Scenario", "current_east_mps", self.current_east_mps, -5.0, 5.0)
        for name in ("forecast_current_north_mps", "forecast_current_east_mps"):
            if getattr(self, name) is not None:
                check_number("Scenario", name, getattr(self, name), -5.0, 5.0)
        if self.endurance_s is not None:
            check_number("Scenario", "endurance_s", self.endurance_s, 10.0, 1e6)
        if not self.area.contains(self.start_north_m, self.start_east_m):
            raise ValueError("Scenario: the start position must lie inside the search area")

    @property
    def primary(self) -> Target:
        return next(t for t in self.targets if t.primary)
