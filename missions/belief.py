"""The search belief of SarSearch-v1: where the victim may be and has not been seen yet, drifting with the water.

A crew plans a search from a probability map (IAMSAR's probability of containment) and lowers it after every
look by the look's probability of detection (Koopman's search theory). Here, on a square grid over the area whose
cells are at most ``MAP_CELL_M`` across whatever the area (:func:`map_cells`: 32 x 32 on the default task's 1 km
square, 64 x 64 on a 2 km one), for N searches at once:

* **prior**: a Gaussian around the datum with the datum's sigma, each cell holding its integral over the cell; what
  lies beyond an edge of the area is kept in the edge cells (the crew assumes the victim is in the area it
  searches, and keeps it there as the blur below does; the scenario generator likewise puts a victim drawn beyond
  the area just inside its edge);
* **drift**: the map moves with the forecast drift of the reported object (``ScenarioBatch.forecast_drift``). It
  stays on the ground grid and moves by whole cells; the part of a cell it has not moved yet is kept as
  ``offset`` (metres, (N, 2)) and added to the cells' positions wherever the map is read, so a look is judged
  against where each cell's water is now, and no interpolation blurs the map as it moves;
* **forecast error**: the forecast current may be off by ``FORECAST_SIGMA_MPS`` per axis (1 sigma), so the
  position error of a drifting object grows as sigma * t; every ``BLUR_EVERY_S`` the map is blurred by the growth
  of that variance since the last blur (a separable 3-tap kernel that keeps the mass at the edges);
* **looks**: a look multiplies the belief of every cell the camera footprint touches by (1 - p), p the detection
  probability of an object of the reported category averaged over the cell (the simulated camera's own model,
  ``missions.search.cell_detection_probability``: exact, and 0 for the part of the cell outside the footprint);
  ``searched`` keeps each cell's cumulative probability of detection, 1 - prod(1 - p), and moves with the map.

Why both the averaged look and the cell size (docs/environment.md, "The map's resolution"): a look that gave a whole
cell the probability at its centre credited water outside the footprint, and a look averaged over the cell spreads
what it found over the whole cell, so that the next look at the same water finds more than is left there. Both
over-state the search by more the larger a cell is against the footprint (35 m half-width at the search altitude);
with cells of at most ``MAP_CELL_M`` and averaged looks, what the map expects to be found is what is found.

``belief`` sums to the probability, under the crew's model, that the victim is in the area and not yet detected.
"""
from __future__ import annotations

import math

import numpy as np

from missions import coverage, search

FORECAST_SIGMA_MPS = 0.05
"""The crew's assumed 1-sigma error of the forecast current per axis (m/s); the generator's SarSearch-v1 draws
its forecast errors with the same sigma (``missions.generator.TASK_V1``)."""
BLUR_EVERY_S = 30.0
"""Seconds between two blurs of the map for the growing forecast error (one blur per meta-controller decision)."""
MAX_PASS_VARIANCE = 0.5
"""Largest variance (cells^2) one pass of the 3-tap kernel [w, 1 - 2w, w] adds (w = 0.25): more takes passes."""
MAP_CELL_M = 1000.0 / coverage.GRID_SIZE
"""Largest side (m) of a map cell: the default task's cell (its 1 km square over 32), a little less than the camera
footprint's half-width at the search altitude. Larger areas get more cells, not larger ones."""

_erf = np.vectorize(math.erf, otypes=[np.float64])


def map_cells(area: np.ndarray) -> int:
    """Cells per side of the map for searches over ``area`` ((N, 4) or (4,)): the fewest that keep every cell of
    every one of these areas at most ``MAP_CELL_M`` across, a multiple of the observation's 16 x 16 summary
    (``coverage.OBS_GRID``), and at least ``coverage.GRID_SIZE``. The memory of a map grows with the square of it
    (8 bytes a cell per grid per search)."""
    side = float(np.max(np.reshape(area, (-1, 4))[:, 1::2] - np.reshape(area, (-1, 4))[:, 0::2]))
    blocks = math.ceil(side / (coverage.OBS_GRID * MAP_CELL_M) - 1e-9)
    return coverage.OBS_GRID * max(blocks, coverage.GRID_SIZE // coverage.OBS_GRID)


def cell_size_m(area: np.ndarray, cells: int) -> np.ndarray:
    """(N, 2) the north and east size of a cell (m) of a ``cells`` x ``cells`` map over ``area`` (N, 4)."""
    return (area[:, 1::2] - area[:, 0::2]) / cells


def prior(area: np.ndarray, datum: np.ndarray, sigma: np.ndarray, cells: int) -> np.ndarray:
    """(N, G, G), G = ``cells``: the Gaussian around ``datum`` (N, 2) with ``sigma`` (N,), each cell holding its
    integral over the cell and the edge cells also what lies beyond their edge of the area, so that each map sums
    to 1 (the north and east parts are independent: a product of two one-axis masses)."""
    root = math.sqrt(2.0) * np.maximum(sigma, 1.0)[:, None]
    inner = np.arange(1, cells) / cells  # the cell boundaries inside the area; beyond the first and last: the tails

    def along(axis: int) -> np.ndarray:
        low, high = area[:, 2 * axis:2 * axis + 1], area[:, 2 * axis + 1:2 * axis + 2]
        below = _erf((low + inner * (high - low) - datum[:, axis:axis + 1]) / root)  # (N, G - 1)
        ones = np.ones((len(area), 1))
        return 0.5 * np.diff(np.concatenate([-ones, below, ones], axis=1), axis=1)

    return along(0)[:, :, None] * along(1)[:, None, :]


def drift(grids: tuple[np.ndarray, ...], offset: np.ndarray, area: np.ndarray, velocity: np.ndarray,
          dt_s: float) -> None:
    """Move the maps ``grids`` (each (N, G, G), in place) with ``velocity`` (N, 2) for ``dt_s``: ``offset`` (N, 2)
    gathers the motion, and each whole cell of it shifts the maps by one cell (what drifts in from beyond the
    area is empty, what drifts out is gone)."""
    offset += velocity * dt_s
    size = cell_size_m(area, grids[0].shape[1])
    for axis in (0, 1):
        for sign in (1, -1):
            rows = np.flatnonzero(sign * offset[:, axis] >= size[:, axis])
            if len(rows) == 0:
                continue  # the common case: a cell of drift takes minutes
            for grid in grids:
                moved = np.roll(grid[rows], sign, axis=axis + 1)
                edge = 0 if sign > 0 else -1
                if axis == 0:
                    moved[:, edge, :] = 0.0
                else:
                    moved[:, :, edge] = 0.0
                grid[rows] = moved
            offset[rows, axis] -= sign * size[rows, axis]


def blur(belief: np.ndarray, variance_cells2: np.ndarray) -> None:
    """Spread ``belief`` (N, G, G) in place by a Gaussian-like kernel adding ``variance_cells2`` (N, 2) along
    north and east; the mass stays on the grid (what would spread beyond an edge stays in the edge cell)."""
    for axis in (0, 1):
        variance = variance_cells2[:, axis]
        passes = int(math.ceil(float(variance.max(initial=0.0)) / MAX_PASS_VARIANCE))
        if passes == 0:
            continue
        w = (variance / (2.0 * passes))[:, None, None]
        for _ in range(passes):
            grid = belief if axis == 0 else belief.transpose(0, 2, 1)  # a view: rows are the axis being blurred
            before, after = np.empty_like(grid), np.empty_like(grid)
            before[:, 1:], before[:, 0] = grid[:, :-1], grid[:, 0]  # the neighbour to the south (or west)
            after[:, :-1], after[:, -1] = grid[:, 1:], grid[:, -1]
            grid[...] = (1.0 - 2.0 * w) * grid + w * (before + after)


def look(belief: np.ndarray, searched: np.ndarray, area: np.ndarray, offset: np.ndarray, drone_ne: np.ndarray,
         altitude_m: np.ndarray, zoom: np.ndarray, intensity: np.ndarray, size_m: np.ndarray,
         factor: np.ndarray) -> np.ndarray:
    """One look of the camera from ``drone_ne`` (N, 2) at ``altitude_m``, ``zoom`` and ``intensity`` (N,): lowers
    ``belief`` and raises ``searched`` (both (N, G, G), in place) in every cell the footprint touches by the detection
    probability, averaged over the cell, of an object of size ``size_m`` (N,) with condition factor ``factor`` (N,)
    (``search.condition_factor`` of the reported category). Returns the belief removed per search (N,), the
    probability this look detects the victim under the crew's model."""
    n, grid = belief.shape[0], belief.shape[1]
    size = cell_size_m(area, grid)
    half_width = search.footprint_half_width_m(altitude_m, zoom)
    reach = int(np.ceil(np.max(half_width[:, None] / size))) + 1  # cells from the drone's to a touched one
    k = min(2 * reach + 1, grid)
    corner = area[:, 0::2] + offset  # where the map's first cell lies now
    own = np.clip(np.floor((drone_ne - corner) / size), 0, grid - 1)
    first = np.clip(own - reach, 0, grid - k).astype(np.int64)  # the K x K window, kept inside the grid
    rows = first[:, 0:1] + np.arange(k)  # (N, K)
    cols = first[:, 1:2] + np.arange(k)
    p = search.cell_detection_probability(drone_ne, corner[:, 0:1] + rows * size[:, 0:1],
                                          corner[:, 1:2] + cols * size[:, 1:2], size, size_m, factor, altitude_m,
                                          zoom, intensity)
    index = np.arange(n)[:, None, None], rows[:, :, None], cols[:, None, :]
    before = belief[index]
    belief[index] = before * (1.0 - p)
    searched[index] = 1.0 - (1.0 - searched[index]) * (1.0 - p)
    return (before * p).sum(axis=(1, 2))
