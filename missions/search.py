"""The search logic shared by training and flight: coverage grid, detection model, drift, end conditions.

Every function is a pure numpy function over arrays with a leading batch dimension N: the vectorised
training environment calls them with N ~ 1024 scenarios at once, the single environment and the flight
runtime with N = 1. There are no Python loops over scenarios or grid cells; functions that update state
(:func:`cover`, :func:`drift_targets`) do so in place on arrays the caller owns. Randomness stays with the
caller: :func:`detection_probability` returns probabilities and :func:`sample_detections` turns them into
detections with uniforms the caller drew from its own seeded generator.

World model (positions are metres (north, east) in the local NED frame of home):

* **Search area and coverage grid.** The area is the rectangle ``north_min..north_max x east_min..east_max``
  (``area`` arrays are (N, 4) in that order). It is divided into ``GRID_SIZE x GRID_SIZE`` cells; row ``i``
  counts north from ``north_min``, column ``j`` east from ``east_min``. The observation sees the grid
  averaged over 2 x 2 blocks (``OBS_GRID x OBS_GRID`` = 256 values, row-major, north rows first).
* **Camera.** A nadir camera with a ``CAMERA_FOV_DEG`` horizontal field of view at zoom 0 and an optical
  zoom factor ``1 + ZOOM_RANGE * zoom`` (zoom in [0, 1] -> 1x..4x). Its footprint is a north/east-aligned
  square with half-width ``h = altitude * tan(FOV / 2) / zoom_factor`` (35.01 m at 50 m and zoom 0).
* **Coverage.** While the sensor is on (search intensity >= ``SENSOR_ON_INTENSITY``) every cell whose centre
  lies inside the footprint becomes covered (1.0), and so does the cell containing the drone (so that a
  footprint smaller than a cell still counts). Coverage never decreases.
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

from missions.mission import Mission
from missions.scenario import CATEGORIES, WIND_FULL_SCALE_MPS, Scenario, SearchArea

GRID_SIZE = 32
"""Cells per side of the coverage grid over the search area (32 x 32 = 1,024 cells)."""
OBS_GRID = GRID_SIZE // 2
"""Cells per side of the observed coverage grid (2 x 2 block means): 16 x 16 = 256 values."""
NUM_CATEGORIES = len(CATEGORIES)

CAMERA_FOV_DEG = 70.0
"""Horizontal field of view of the camera at zoom 0 (degrees)."""
TAN_HALF_FOV = math.tan(math.radians(CAMERA_FOV_DEG / 2.0))
ZOOM_RANGE = 3.0
"""Optical zoom factor is 1 + ZOOM_RANGE * zoom: zoom 0 -> 1x, zoom 1 -> 4x."""
SENSOR_ON_INTENSITY = 0.5
"""Search intensity at or above which the sensor counts as on for coverage."""

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

    @classmethod
    def from_missions(cls, missions: Sequence[Mission], **padding: int | None) -> ScenarioBatch:
        """Stack the scenarios of :class:`missions.mission.Mission` objects with their geofences."""
        return cls.from_scenarios([m.scenario for m in missions], [m.fence for m in missions], **padding)

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


def sample_detections(probability: np.ndarray, uniform: np.ndarray) -> np.ndarray:
    """(N, T) bool detections from probabilities and the caller's uniforms in [0, 1) (same shape)."""
    return uniform < probability


def detected_categories(detections: np.ndarray, category: np.ndarray) -> np.ndarray:
    """(N, 6) bool: whether an object of each category (CATEGORIES order) was detected."""
    found = np.zeros((detections.shape[0], NUM_CATEGORIES), dtype=bool)
    found[detections.nonzero()[0], category[detections]] = True
    return found


# --------------------------------------------------------------------------------------------- coverage


def grid_cell(area: np.ndarray, north: np.ndarray, east: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(row, col) int64 arrays of the cells containing (north, east), clipped to [0, GRID_SIZE - 1]."""
    row = np.floor((north - area[:, 0]) * (GRID_SIZE / (area[:, 1] - area[:, 0])))
    col = np.floor((east - area[:, 2]) * (GRID_SIZE / (area[:, 3] - area[:, 2])))
    return (np.clip(row, 0, GRID_SIZE - 1).astype(np.int64), np.clip(col, 0, GRID_SIZE - 1).astype(np.int64))


_OFFSETS = np.arange(GRID_SIZE, dtype=np.float64)
_BASE_CACHE: dict[int, np.ndarray] = {}


def _flat_base(n: int) -> np.ndarray:
    """(N,) offsets of each scenario's grid in the flattened coverage (cached: the same N every step)."""
    base = _BASE_CACHE.get(n)
    if base is None:
        base = _BASE_CACHE[n] = np.arange(n, dtype=np.float64) * (GRID_SIZE * GRID_SIZE)
    return base


def cover(coverage: np.ndarray, area: np.ndarray, drone_ne: np.ndarray, half_width: np.ndarray | float,
          intensity: np.ndarray | float) -> np.ndarray:
    """Mark the cells seen this step as covered, in place; returns newly covered cells per scenario (N,).

    coverage: (N, GRID_SIZE, GRID_SIZE) float32, C-contiguous, owned by the caller; area (N, 4);
    drone_ne (N, 2); half_width (N,) or scalar, from :func:`footprint_half_width_m`; intensity (N,) or scalar.
    """
    if not coverage.flags.c_contiguous:
        raise ValueError("cover: coverage must be C-contiguous (it is updated through a flat view)")
    n = coverage.shape[0]
    if n == 1:  # the single environment and the flight runtime: plain slices beat numpy's per-call overhead
        return _cover_one(coverage[0], area[0], drone_ne[0], float(np.reshape(half_width, -1)[0]),
                          float(np.reshape(intensity, -1)[0]))
    # Both axes at once, as (2, N) arrays (north row, east row) so that numpy's inner loops run over N:
    # area[:, 0::2] is (north_min, east_min) per scenario, area[:, 1::2] the maxima.
    low = area[:, 0::2]
    cells_per_m = GRID_SIZE / (area[:, 1::2] - low)
    u = ((drone_ne - low) * cells_per_m).T  # drone position in cell units; the centre of cell k sits at k + 0.5
    reach = np.reshape(half_width, (1, -1)) * cells_per_m.T  # footprint half-width in cell units
    # The drone's own cell; a drone exactly on the far edge of the area is in the last cell, and a drone
    # outside the area gets an index outside the grid, which no window below contains.
    own = np.floor(u)
    own -= u == GRID_SIZE

    # Update a K x K window per scenario instead of the whole grid: the footprint spans a few cells, so this
    # touches N * K * K values rather than N * 1024. A cell whose centre is within reach is at most
    # floor(reach + 0.5) cells from the own cell, so the window own +- m holds them all; it is shifted to lie
    # inside the grid, which keeps its cells distinct (the gather / scatter below never writes a cell twice).
    m = int(reach.max() + 0.5)
    k = min(2 * m + 1, GRID_SIZE)
    index = np.minimum(np.maximum(own - m, 0.0), GRID_SIZE - k)[:, None, :] + _OFFSETS[:k, None]  # (2, K, N)
    centre_in = np.abs(index - (u - 0.5)[:, None, :]) <= reach[:, None, :]
    own_cell = index == own[:, None, :]
    seen = centre_in[0, :, None] & centre_in[1, None]  # (K, K, N): the cell centre is inside the footprint
    seen |= own_cell[0, :, None] & own_cell[1, None]  # or the drone is over the cell
    seen &= np.reshape(intensity, -1) >= SENSOR_ON_INTENSITY

    flat_index = ((index[0] * GRID_SIZE + _flat_base(n))[:, None] + index[1, None]).astype(np.int64)
    flat = coverage.reshape(-1)
    before = flat[flat_index]
    after = np.maximum(before, seen)
    flat[flat_index] = after
    after -= before
    return after.sum(axis=(0, 1), dtype=np.int64)


def _cover_one(grid: np.ndarray, area: np.ndarray, drone_ne: np.ndarray, half_width: float,
               intensity: float) -> np.ndarray:
    """:func:`cover` for one scenario, with the same rule: the cells whose centres lie in the footprint form
    a rectangle of rows and columns, plus the drone's own cell."""
    if intensity < SENSOR_ON_INTENSITY:
        return np.zeros(1, dtype=np.int64)
    ranges = []
    for axis in (0, 1):
        low, high = float(area[2 * axis]), float(area[2 * axis + 1])
        cells_per_m = GRID_SIZE / (high - low)
        u = (float(drone_ne[axis]) - low) * cells_per_m
        reach = half_width * cells_per_m
        own = math.floor(u) - (u == GRID_SIZE)
        first = max(math.ceil(u - 0.5 - reach), 0)  # |k + 0.5 - u| <= reach
        last = min(math.floor(u - 0.5 + reach), GRID_SIZE - 1)
        ranges.append((first, last, own))
    (r0, r1, own_row), (c0, c1, own_col) = ranges
    newly = 0
    if r0 <= r1 and c0 <= c1:
        block = grid[r0:r1 + 1, c0:c1 + 1]
        newly = block.size - int(np.count_nonzero(block))
        block[...] = 1.0
    if 0 <= own_row < GRID_SIZE and 0 <= own_col < GRID_SIZE and grid[own_row, own_col] == 0.0:
        grid[own_row, own_col] = 1.0
        newly += 1
    return np.array([newly], dtype=np.int64)


def downsample_coverage(coverage: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """(N, OBS_GRID * OBS_GRID) float32: means of 2 x 2 blocks, row-major with north rows first.

    ``out`` may be a preallocated (N, OBS_GRID, OBS_GRID) or (N, 256) float32 array to fill.
    """
    n = coverage.shape[0]
    rows = coverage[:, 0::2, :] + coverage[:, 1::2, :]  # (N, 16, 32): pairs of rows (contiguous runs)
    if out is None:
        out = np.empty((n, OBS_GRID * OBS_GRID), dtype=np.float32)
    blocks = out.reshape(n, OBS_GRID, OBS_GRID)
    np.add(rows[:, :, 0::2], rows[:, :, 1::2], out=blocks)
    blocks *= 0.25
    return out.reshape(n, OBS_GRID * OBS_GRID)


def coverage_ratio(coverage: np.ndarray) -> np.ndarray:
    """(N,) share of covered cells (the paper's coverage metric)."""
    return coverage.mean(axis=(1, 2))


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


def target_reached(drone_ne: np.ndarray, target_ne: np.ndarray, primary_index: np.ndarray,
                   reach_radius_m: np.ndarray | float) -> np.ndarray:
    """(N,) bool: the primary target is within reach_radius_m (horizontally)."""
    return distance_to_primary(drone_ne, target_ne, primary_index) <= reach_radius_m


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
