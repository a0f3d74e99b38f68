"""The search logic shared by training and flight: coverage grid, detection model, drift, end conditions.

Every function is a pure numpy function over arrays with a leading batch dimension N: the vectorised
training environment calls them with N ~ 1024 scenarios at once, the single environment and the flight
runtime with N = 1. There are no Python loops over scenarios or grid cells; functions that update state
(:func:`~missions.coverage.cover`, :func:`drift_targets`) do so in place on arrays the caller owns. Randomness
stays with the caller: :func:`detection_probability` returns probabilities, which the caller compares with
uniforms it drew from its own seeded generator.

World model (positions are metres (north, east) in the local NED frame of home):

* **Search area and coverage grid.** The area is the rectangle ``north_min..north_max x east_min..east_max``
  (``area`` arrays are (N, 4) in that order), divided into the coverage grid of ``missions/coverage.py``.
* **Camera.** A nadir camera with a ``CAMERA_FOV_DEG`` horizontal field of view at zoom 0 and an optical
  zoom factor ``1 + ZOOM_RANGE * zoom`` (zoom in [0, 1] -> 1x..4x). Its footprint is a north/east-aligned
  square with half-width ``h = altitude * tan(FOV / 2) / zoom_factor`` (35.01 m at 50 m and zoom 0).
* **Detection.** A target can only be detected inside the footprint. Per step it is detected with
  probability ``p = intensity * DETECTION_CEILING * f_range * f_res * f_vis * f_weather * f_time * f_sea``:
  ``f_range = 1 - 0.5 (r / h)^2`` (r = horizontal distance; image edges are worse than the centre),
  ``f_res = 1 - exp(-size * zoom_factor * RESOLUTION_SCALE / altitude)`` (how many pixels the object
  covers), ``f_vis`` = visibility, and the factor tables ``WEATHER_FACTOR``, ``TIME_FACTOR`` and
  ``SEA_FACTOR`` (objects larger than ``LARGE_OBJECT_M`` use the square root of the sea factor: a boat is
  not hidden by waves; see ``SEA_FACTOR_BY_CATEGORY``).
* **Drift.** Objects drift with the sea current plus ``LEEWAY[category]`` times the wind velocity
  (``Conditions.wind * WIND_FULL_SCALE_MPS`` towards ``Conditions.wind_direction_deg``).
* **End conditions.** The primary target is reached when the horizontal distance to it is at most the
  reach radius; a collision is the drone inside (or on the rim of) an obstacle circle; a boundary violation
  is the drone outside the geofence rectangle (the search area unless a mission sets a geofence).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Sequence

import numpy as np

# The coverage grid is missions/coverage.py; the training environment and the flight runtime still reach these
# names as ``search.X`` (policies/env/, autonomy/observation.py, missions/search_state_v0.py and _v1.py).
from missions.coverage import GRID_SIZE, SENSOR_ON_INTENSITY, cover, downsample_coverage  # noqa: F401
from missions.scenario import CATEGORIES, WIND_FULL_SCALE_MPS, Scenario, SearchArea

NUM_CATEGORIES = len(CATEGORIES)

CAMERA_FOV_DEG = 70.0
"""Horizontal field of view of the camera at zoom 0 (degrees)."""
TAN_HALF_FOV = math.tan(math.radians(CAMERA_FOV_DEG / 2.0))
ZOOM_RANGE = 3.0
"""Optical zoom factor is 1 + ZOOM_RANGE * zoom: zoom 0 -> 1x, zoom 1 -> 4x."""

DETECTION_CEILING = 0.98
"""Best per-step detection probability (even a perfect view misses now and then)."""
RESOLUTION_SCALE = 150.0
"""Scale of f_res: an object of size s (m) at altitude a (m) and zoom factor z gives 1 - exp(-s z 150 / a)."""
LARGE_OBJECT_M = 3.0
"""Objects larger than this are not hidden by waves: they use sqrt(SEA_FACTOR)."""


def _table(values: Sequence[float]) -> np.ndarray:
    array = np.array(values, dtype=np.float64)
    array.setflags(write=False)  # module constants: nobody may change the world model by accident
    return array


OBJECT_SIZE_M = _table([0.5, 6.0, 0.6, 1.5, 1.0, 0.6])
"""Characteristic size (m) per category, CATEGORIES order: person, boat, life_jacket, debris, floating_object,
swimmer."""
LEEWAY = _table([0.03, 0.04, 0.05, 0.02, 0.03, 0.02])
"""Share of the wind speed each category drifts with (CATEGORIES order)."""
WEATHER_FACTOR = _table([1.0, 0.9, 0.5, 0.7])
"""Detection factor per Weather: clear, cloudy, foggy, rainy."""
TIME_FACTOR = _table([0.75, 1.0, 0.7, 0.35])
"""Detection factor per TimeOfDay: dawn, day, dusk, night."""
SEA_FACTOR = _table([1.0, 0.8, 0.55])
"""Detection factor per SeaState: calm, moderate, rough (small objects hide in the waves)."""
SEA_FACTOR_BY_CATEGORY = _table(np.where(OBJECT_SIZE_M[None, :] > LARGE_OBJECT_M,
                                         np.sqrt(SEA_FACTOR)[:, None], SEA_FACTOR[:, None]))
"""(3, 6): the sea factor per SeaState (rows) and category (columns), sqrt for large objects."""

_FAR_M = 1e7  # where padding targets sit: never in a footprint, never reached, no NaN arithmetic


@dataclass(eq=False)  # arrays do not compare to a single bool
class ScenarioBatch:
    """N scenarios as arrays, padded to T targets and O obstacles (padding is marked invalid).

    Built once per reset from :class:`Scenario` objects; the arrays are then read by the step functions of
    this module. ``targets`` holds the initial target positions (callers copy it before drifting).
    """

    area: np.ndarray
    """(N, 4) float64: north_min, north_max, east_min, east_max of the search area."""
    fence: np.ndarray
    """(N, 4) float64, same layout: the geofence (the area unless a mission sets a geofence)."""
    start: np.ndarray
    """(N, 2) float64: start position (north, east)."""
    datum: np.ndarray
    """(N, 2) float64: last known position of the victim."""
    datum_sigma: np.ndarray
    """(N,) float64: 1-sigma uncertainty of the datum (m)."""
    targets: np.ndarray
    """(N, T, 2) float64: initial target positions; padding sits far away."""
    target_category: np.ndarray
    """(N, T) int64: index into CATEGORIES (0 for padding)."""
    target_valid: np.ndarray
    """(N, T) bool: False for padding."""
    primary_index: np.ndarray
    """(N,) int64: index of the primary target (0, a padding slot, when a scenario has no targets)."""
    obstacles: np.ndarray
    """(N, O, 3) float64: north, east, radius; padding has radius 0."""
    obstacle_valid: np.ndarray
    """(N, O) bool: False for padding."""
    sea: np.ndarray
    """(N,) int64 SeaState."""
    weather: np.ndarray
    """(N,) int64 Weather."""
    time_of_day: np.ndarray
    """(N,) int64 TimeOfDay."""
    visibility: np.ndarray
    """(N,) float64 in [0.3, 1]."""
    wind: np.ndarray
    """(N,) float64 in [0, 1] (fraction of WIND_FULL_SCALE_MPS)."""
    drift_velocity: np.ndarray
    """(N, T, 2) float64 m/s: current + leeway * wind, per target (0 for padding)."""
    seeds: np.ndarray
    """(N,) int64: Scenario.seed, the seed of the randomness while the scenario is flown."""
    forecast_drift: np.ndarray
    """(N, 2) float64 m/s: the drift the crew forecasts for the reported object: the forecast current (the true one
    unless the scenario sets a forecast) plus its category's leeway times the wind."""
    endurance_s: np.ndarray
    """(N,) float64: Scenario.endurance_s (inf when unlimited)."""

    def datum_at(self, time_s: np.ndarray) -> np.ndarray:
        """(N, 2) the datum drifted to ``time_s`` (N,) seconds into the search.

        A SAR planner moves the datum with the forecast total water current plus the leeway of the reported
        object (IAMSAR's datum computation); the reported object is the primary target's category, the forecast
        the scenario's (its true current and wind unless it sets a forecast current). Nothing else about the
        victim is used."""
        return self.datum + self.forecast_drift * np.reshape(time_s, (-1, 1))
    target_size_m: np.ndarray = field(init=False)
    """(N, T) float64, derived: OBJECT_SIZE_M of each target (0 for padding)."""
    detection_factor: np.ndarray = field(init=False)
    """(N, T) float64, derived: :func:`condition_factor` times validity (computed once, used every step)."""

    def __post_init__(self) -> None:
        self.target_size_m = OBJECT_SIZE_M[self.target_category] * self.target_valid
        self.detection_factor = condition_factor(self.target_category, self.sea, self.weather, self.time_of_day,
                                                 self.visibility) * self.target_valid

    def __len__(self) -> int:
        return self.area.shape[0]

    @classmethod
    def from_scenarios(cls, scenarios: Sequence[Scenario], fences: Sequence[SearchArea | None] | None = None, *,
                       num_targets: int | None = None, num_obstacles: int | None = None) -> ScenarioBatch:
        """Stack scenarios; ``fences[i]`` (None = the area) is scenario i's geofence.

        ``num_targets`` / ``num_obstacles`` fix the padded sizes T and O (default: the largest in the batch,
        at least 1), so that batches built at different times can be :meth:`assign`-ed into each other.
        """
        n = len(scenarios)
        if n == 0:
            raise ValueError("ScenarioBatch.from_scenarios needs at least one scenario")
        if fences is not None and len(fences) != n:
            raise ValueError(f"ScenarioBatch.from_scenarios: {len(fences)} fences for {n} scenarios")
        t_needed = max(1, max(len(s.targets) for s in scenarios))
        o_needed = max(1, max(len(s.obstacles) for s in scenarios))
        t = t_needed if num_targets is None else num_targets
        o = o_needed if num_obstacles is None else num_obstacles
        if t < t_needed or o < o_needed:
            raise ValueError(f"ScenarioBatch.from_scenarios: num_targets/num_obstacles ({t}, {o}) below what the "
                             f"scenarios hold ({t_needed}, {o_needed})")

        def rect(a: SearchArea) -> tuple[float, float, float, float]:
            return a.north_min_m, a.north_max_m, a.east_min_m, a.east_max_m

        targets = np.full((n, t, 2), _FAR_M)
        category = np.zeros((n, t), dtype=np.int64)
        valid = np.zeros((n, t), dtype=bool)
        primary = np.zeros(n, dtype=np.int64)
        obstacles = np.zeros((n, o, 3))
        obstacle_valid = np.zeros((n, o), dtype=bool)
        current = np.zeros((n, 2))
        wind_dir = np.zeros(n)
        for i, s in enumerate(scenarios):  # once per reset, not per step
            for k, target in enumerate(s.targets):
                targets[i, k] = target.north_m, target.east_m
                category[i, k] = CATEGORIES.index(target.category)
                valid[i, k] = True
                if target.primary:
                    primary[i] = k
            for k, obstacle in enumerate(s.obstacles):
                obstacles[i, k] = obstacle.north_m, obstacle.east_m, obstacle.radius_m
                obstacle_valid[i, k] = True
            current[i] = s.current_north_mps, s.current_east_mps
            wind_dir[i] = s.conditions.wind_direction_deg
        area = np.array([rect(s.area) for s in scenarios], dtype=np.float64)
        fence = area.copy() if fences is None else np.array(
            [rect(f if f is not None else s.area) for s, f in zip(scenarios, fences)], dtype=np.float64)
        wind = np.array([s.conditions.wind for s in scenarios], dtype=np.float64)
        forecast_current = np.array([(s.current_north_mps if s.forecast_current_north_mps is None
                                      else s.forecast_current_north_mps,
                                      s.current_east_mps if s.forecast_current_east_mps is None
                                      else s.forecast_current_east_mps) for s in scenarios], dtype=np.float64)
        reported = category[np.arange(n), primary]
        has_targets = valid[np.arange(n), primary][:, None]
        return cls(
            area=area, fence=fence,
            start=np.array([(s.start_north_m, s.start_east_m) for s in scenarios], dtype=np.float64),
            datum=np.array([(s.datum_north_m, s.datum_east_m) for s in scenarios], dtype=np.float64),
            datum_sigma=np.array([s.datum_sigma_m for s in scenarios], dtype=np.float64),
            targets=targets, target_category=category, target_valid=valid, primary_index=primary,
            obstacles=obstacles, obstacle_valid=obstacle_valid,
            sea=np.array([int(s.conditions.sea) for s in scenarios], dtype=np.int64),
            weather=np.array([int(s.conditions.weather) for s in scenarios], dtype=np.int64),
            time_of_day=np.array([int(s.conditions.time_of_day) for s in scenarios], dtype=np.int64),
            visibility=np.array([s.conditions.visibility for s in scenarios], dtype=np.float64),
            wind=wind,
            drift_velocity=target_drift_velocity(category, wind[:, None], wind_dir[:, None], current[:, None, :])
            * valid[:, :, None],  # padding stays put
            seeds=np.array([s.seed for s in scenarios], dtype=np.int64),
            forecast_drift=target_drift_velocity(reported, wind, wind_dir, forecast_current) * has_targets,
            endurance_s=np.array([np.inf if s.endurance_s is None else s.endurance_s for s in scenarios]),
        )

    def select(self, index: int | slice | Sequence[int] | np.ndarray) -> ScenarioBatch:
        """A sub-batch (copies); an integer index keeps the batch dimension (N = 1)."""
        if isinstance(index, (int, np.integer)):
            index = slice(int(index), int(index) + 1 if index != -1 else None)
        return ScenarioBatch(**{f.name: getattr(self, f.name)[index].copy() for f in fields(self) if f.init})

    def assign(self, index: int | slice | Sequence[int] | np.ndarray, other: ScenarioBatch) -> None:
        """Overwrite the scenarios at ``index`` with ``other`` (e.g. a freshly drawn scenario at a reset).

        ``other`` may have fewer target/obstacle slots than this batch; the rest is filled with padding.
        """
        t, o = self.targets.shape[1], self.obstacles.shape[1]
        if other.targets.shape[1] > t or other.obstacles.shape[1] > o:
            raise ValueError(f"ScenarioBatch.assign: other has {other.targets.shape[1]} target and "
                             f"{other.obstacles.shape[1]} obstacle slots, this batch only {t} and {o}")
        if isinstance(index, (int, np.integer)):
            index = [int(index)]
        pads = {"targets": _FAR_M, "target_category": 0, "target_valid": False, "drift_velocity": 0.0,
                "obstacles": 0.0, "obstacle_valid": False, "target_size_m": 0.0, "detection_factor": 0.0}
        for f in fields(self):
            mine, theirs = getattr(self, f.name), getattr(other, f.name)
            if f.name in pads and theirs.shape[1] < mine.shape[1]:
                padded = np.full((theirs.shape[0],) + mine.shape[1:], pads[f.name], dtype=mine.dtype)
                padded[:, :theirs.shape[1]] = theirs
                theirs = padded
            mine[index] = theirs

    def detection_probability(self, drone_ne: np.ndarray, target_ne: np.ndarray, altitude_m: np.ndarray | float,
                              zoom: np.ndarray | float, intensity: np.ndarray | float) -> np.ndarray:
        """:func:`detection_probability` for this batch's targets and conditions, (N, T); the per-scenario
        factors were computed once at construction."""
        return detection_probability_from_factors(drone_ne, target_ne, self.target_size_m, self.detection_factor,
                                                  altitude_m, zoom, intensity)


# ----------------------------------------------------------------------------------------------- camera


def footprint_half_width_m(altitude_m: np.ndarray | float, zoom: np.ndarray | float) -> np.ndarray:
    """Half-width (m) of the square camera footprint: altitude * tan(FOV / 2) / (1 + ZOOM_RANGE * zoom)."""
    return np.asarray(altitude_m, dtype=np.float64) * TAN_HALF_FOV / (1.0 + ZOOM_RANGE * np.asarray(zoom))


def condition_factor(category: np.ndarray, sea: np.ndarray, weather: np.ndarray, time_of_day: np.ndarray,
                     visibility: np.ndarray) -> np.ndarray:
    """(N, T) the part of the detection probability that is fixed for a scenario:
    DETECTION_CEILING * f_vis * f_weather * f_time * f_sea (sea factor per target category)."""
    scene = DETECTION_CEILING * visibility * WEATHER_FACTOR[weather] * TIME_FACTOR[time_of_day]
    return SEA_FACTOR_BY_CATEGORY[sea[:, None], category] * scene[:, None]


def detection_probability(drone_ne: np.ndarray, target_ne: np.ndarray, category: np.ndarray, valid: np.ndarray,
                          altitude_m: np.ndarray | float, zoom: np.ndarray | float, intensity: np.ndarray | float,
                          sea: np.ndarray, weather: np.ndarray, time_of_day: np.ndarray,
                          visibility: np.ndarray) -> np.ndarray:
    """(N, T) probability that each target is detected this step (0 outside the footprint and for padding).

    drone_ne (N, 2), target_ne (N, T, 2) in metres; category (N, T) int; valid (N, T) bool; altitude_m, zoom
    and intensity (N,) or scalars; sea, weather, time_of_day (N,) enum values; visibility (N,).
    The formula and its factor tables are described in the module docstring. (:meth:`ScenarioBatch.
    detection_probability` is the same computation with the per-scenario factors computed once.)
    """
    factor = condition_factor(category, sea, weather, time_of_day, visibility) * valid
    return detection_probability_from_factors(drone_ne, target_ne, OBJECT_SIZE_M[category], factor, altitude_m,
                                              zoom, intensity)


def detection_probability_from_factors(drone_ne: np.ndarray, target_ne: np.ndarray, size_m: np.ndarray,
                                       factor: np.ndarray, altitude_m: np.ndarray | float,
                                       zoom: np.ndarray | float, intensity: np.ndarray | float) -> np.ndarray:
    """The per-step part of :func:`detection_probability`, given the targets' sizes (N, T) in metres and their
    :func:`condition_factor` (N, T), multiplied by validity (0 for padding)."""
    # Column vectors (N, 1) so that everything broadcasts against the (N, T) target arrays.
    altitude = np.reshape(altitude_m, (-1, 1))
    zoom_factor = 1.0 + ZOOM_RANGE * np.reshape(zoom, (-1, 1))
    half_width = altitude * (TAN_HALF_FOV / zoom_factor)
    dn = target_ne[:, :, 0] - drone_ne[:, 0:1]
    de = target_ne[:, :, 1] - drone_ne[:, 1:2]
    in_view = np.maximum(np.abs(dn), np.abs(de)) <= half_width  # the footprint is a square
    if not in_view.any():  # the common case far from everything: nothing to compute
        return np.zeros(in_view.shape)

    f_range = (dn * dn + de * de) * (-0.5 / (half_width * half_width)) + 1.0
    np.maximum(f_range, 0.0, out=f_range)  # the square's corners lie at r = h * sqrt(2): factor 0, never below
    f_res = 1.0 - np.exp(size_m * (zoom_factor * -RESOLUTION_SCALE / altitude))
    p = f_range * f_res
    p *= factor
    p *= np.reshape(intensity, (-1, 1)) * in_view
    return p


def cell_detection_probability(drone_ne: np.ndarray, north_low: np.ndarray, east_low: np.ndarray,
                               cell_m: np.ndarray, size_m: np.ndarray, factor: np.ndarray,
                               altitude_m: np.ndarray | float, zoom: np.ndarray | float,
                               intensity: np.ndarray | float) -> np.ndarray:
    """(N, R, C) the detection probability of :func:`detection_probability_from_factors` averaged over each cell of
    a grid: an object of size ``size_m`` (N,) with condition factor ``factor`` (N,), equally likely anywhere in the
    cell, is detected by this look with this probability. Cell (i, j) spans ``north_low[:, i]`` to ``north_low[:, i]
    + cell_m[:, 0]`` and ``east_low[:, j]`` to ``east_low[:, j] + cell_m[:, 1]`` (north_low (N, R), east_low (N, C),
    cell_m (N, 2), metres).

    Exact, not sampled: inside the square footprint ``f_range = 1 - 0.5 (dn^2 + de^2) / h^2`` is a sum of a term in
    dn and a term in de (and never below 0 there), so its integral over the part of the cell inside the footprint is
    a product of interval lengths and cubes. Outside the footprint p is 0, so a cell the footprint misses keeps 0."""
    altitude = np.reshape(altitude_m, (-1, 1))
    zoom_factor = 1.0 + ZOOM_RANGE * np.reshape(zoom, (-1, 1))
    half_width = altitude * (TAN_HALF_FOV / zoom_factor)  # (N, 1)

    def along(low: np.ndarray, size: np.ndarray, drone: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per cell of one axis: the length of its part inside the footprint and the integral of d^2 over it."""
        start = np.clip(low - drone[:, None], -half_width, half_width)
        end = np.clip(low + size[:, None] - drone[:, None], -half_width, half_width)
        return end - start, (end ** 3 - start ** 3) / 3.0

    length_n, square_n = along(north_low, cell_m[:, 0], drone_ne[:, 0])
    length_e, square_e = along(east_low, cell_m[:, 1], drone_ne[:, 1])
    inverse = (-0.5 / (half_width * half_width))[:, :, None]
    integral = length_n[:, :, None] * length_e[:, None, :] + inverse * (square_n[:, :, None] * length_e[:, None, :]
                                                                         + length_n[:, :, None] * square_e[:, None, :])
    f_res = 1.0 - np.exp(np.reshape(size_m, (-1, 1)) * (zoom_factor * -RESOLUTION_SCALE / altitude))  # (N, 1)
    scale = f_res[:, 0] * np.reshape(factor, -1) * np.reshape(intensity, -1) / (cell_m[:, 0] * cell_m[:, 1])
    return np.maximum(integral, 0.0) * scale[:, None, None]


def detected_categories(detections: np.ndarray, category: np.ndarray) -> np.ndarray:
    """(N, 6) bool: whether an object of each category (CATEGORIES order) was detected."""
    found = np.zeros((detections.shape[0], NUM_CATEGORIES), dtype=bool)
    found[detections.nonzero()[0], category[detections]] = True
    return found


# -------------------------------------------------------------------------------------- drift and events


def target_drift_velocity(category: np.ndarray, wind: np.ndarray | float, wind_direction_deg: np.ndarray | float,
                          current_ne: np.ndarray) -> np.ndarray:
    """(..., 2) drift velocity (m/s): current + LEEWAY[category] * wind velocity (wind blowing towards the
    direction, degrees clockwise from north). Arguments broadcast; current_ne has a trailing axis of 2."""
    direction = np.radians(wind_direction_deg)
    speed = LEEWAY[category] * (np.asarray(wind) * WIND_FULL_SCALE_MPS)
    return np.stack([speed * np.cos(direction), speed * np.sin(direction)], axis=-1) + current_ne


def drift_targets(target_ne: np.ndarray, drift_velocity: np.ndarray, dt_s: float) -> None:
    """Move targets (N, T, 2) by drift_velocity * dt_s, in place."""
    target_ne += drift_velocity * dt_s


def distance_to_primary(drone_ne: np.ndarray, target_ne: np.ndarray, primary_index: np.ndarray) -> np.ndarray:
    """(N,) horizontal distance (m) from the drone to the primary target."""
    primary = target_ne[np.arange(target_ne.shape[0]), primary_index]
    return np.hypot(primary[:, 0] - drone_ne[:, 0], primary[:, 1] - drone_ne[:, 1])


def inside_obstacle(drone_ne: np.ndarray, obstacles: np.ndarray, obstacle_valid: np.ndarray) -> np.ndarray:
    """(N,) bool: the drone is inside or on the rim of any valid obstacle circle (N, O, 3)."""
    dn = obstacles[:, :, 0] - drone_ne[:, 0:1]
    de = obstacles[:, :, 1] - drone_ne[:, 1:2]
    radius = obstacles[:, :, 2]
    return ((dn * dn + de * de <= radius * radius) & obstacle_valid).any(axis=1)


def outside_fence(drone_ne: np.ndarray, fence: np.ndarray) -> np.ndarray:
    """(N,) bool: the drone is outside the fence rectangle (N, 4); the edges count as inside."""
    north, east = drone_ne[:, 0], drone_ne[:, 1]
    return (north < fence[:, 0]) | (north > fence[:, 1]) | (east < fence[:, 2]) | (east > fence[:, 3])
