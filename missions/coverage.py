"""The coverage grid over the search area: which cells the camera has seen, for N searches at once.

* **Grid.** The area is the rectangle ``north_min..north_max x east_min..east_max`` (``area`` arrays are (N, 4)
  in that order). It is divided into ``GRID_SIZE x GRID_SIZE`` cells; row ``i`` counts north from ``north_min``,
  column ``j`` east from ``east_min``. The observation sees the grid averaged over 2 x 2 blocks
  (``OBS_GRID x OBS_GRID`` = 256 values, row-major, north rows first).
* **Coverage.** While the sensor is on (search intensity >= ``SENSOR_ON_INTENSITY``) every cell whose centre
  lies inside the footprint becomes covered (1.0), and so does the cell containing the drone (so that a
  footprint smaller than a cell still counts). Coverage never decreases.

The camera's footprint (its half-width, :func:`missions.search.footprint_half_width_m`) is the caller's:
:func:`cover` takes it, so that this module needs nothing of the camera model.
"""
from __future__ import annotations

import math

import numpy as np

GRID_SIZE = 32
"""Cells per side of the coverage grid over the search area (32 x 32 = 1,024 cells)."""
OBS_GRID = GRID_SIZE // 2
"""Cells per side of the observed coverage grid (2 x 2 block means): 16 x 16 = 256 values."""
SENSOR_ON_INTENSITY = 0.5
"""Search intensity at or above which the sensor counts as on for coverage."""


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
    """(N, OBS_GRID * OBS_GRID) float32: means of square blocks (2 x 2 of the 32 x 32 grid; B x B of a finer grid
    with B * OBS_GRID cells per side, such as the belief map of a larger area, ``missions.belief.map_cells``),
    row-major with north rows first.

    ``out`` may be a preallocated (N, OBS_GRID, OBS_GRID) or (N, 256) float32 array to fill.
    """
    n, side = coverage.shape[0], coverage.shape[1] // OBS_GRID
    rows = coverage[:, 0::side, :] + coverage[:, 1::side, :]  # (N, 16, G): sums of runs of rows (strided adds)
    for k in range(2, side):
        rows += coverage[:, k::side, :]
    if out is None:
        out = np.empty((n, OBS_GRID * OBS_GRID), dtype=np.float32)
    blocks = out.reshape(n, OBS_GRID, OBS_GRID)
    np.add(rows[:, :, 0::side], rows[:, :, 1::side], out=blocks)
    for k in range(2, side):
        blocks += rows[:, :, k::side]
    blocks *= 1.0 / (side * side)
    return out.reshape(n, OBS_GRID * OBS_GRID)
