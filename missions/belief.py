"""The search belief of SarSearch-v1: where the victim may be and has not been seen yet, drifting with the water.

A crew plans a search from a probability map (IAMSAR's probability of containment) and lowers it after every
look by the look's probability of detection (Koopman's search theory). Here, on the 32 x 32 grid over the area
(``missions.coverage.GRID_SIZE``), for N searches at once:

* **prior**: a Gaussian around the datum with the datum's sigma at the cell centres, normalised over the area
  (the crew assumes the victim is in the area it searches);
* **drift**: the map moves with the forecast drift of the reported object (``ScenarioBatch.forecast_drift``). It
  stays on the ground grid and moves by whole cells; the part of a cell it has not moved yet is kept as
  ``offset`` (metres, (N, 2)) and added to the cell centres wherever the map is read, so a look is judged against
  where each cell's water is now, and no interpolation blurs the map as it moves;
* **forecast error**: the forecast current may be off by ``FORECAST_SIGMA_MPS`` per axis (1 sigma), so the
  position error of a drifting object grows as sigma * t; every ``BLUR_EVERY_S`` the map is blurred by the growth
  of that variance since the last blur (a separable 3-tap kernel that keeps the mass at the edges);
* **looks**: a look multiplies the belief of every cell whose centre is in the camera footprint by (1 - p), p the
  detection probability of an object of the reported category at the cell centre (the simulated camera's own
  model, ``missions.search``); ``searched`` keeps each cell's cumulative probability of detection,
  1 - prod(1 - p), and moves with the map.

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


def cell_size_m(area: np.ndarray) -> np.ndarray:
    """(N, 2) the north and east size of a grid cell (m)."""
    return (area[:, 1::2] - area[:, 0::2]) / coverage.GRID_SIZE


def prior(area: np.ndarray, datum: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """(N, G, G) the Gaussian around ``datum`` (N, 2) with ``sigma`` (N,) at the cell centres, summing to 1."""
    fractions = (np.arange(coverage.GRID_SIZE) + 0.5) / coverage.GRID_SIZE
    north = area[:, 0:1] + fractions * (area[:, 1:2] - area[:, 0:1])
    east = area[:, 2:3] + fractions * (area[:, 3:4] - area[:, 2:3])
    two_sigma2 = 2.0 * np.maximum(sigma, 1.0)[:, None] ** 2
    along_north = np.exp(-(north - datum[:, 0:1]) ** 2 / two_sigma2)
    along_east = np.exp(-(east - datum[:, 1:2]) ** 2 / two_sigma2)
    grid = along_north[:, :, None] * along_east[:, None, :]
    total = grid.sum(axis=(1, 2), keepdims=True)
    return np.divide(grid, total, out=np.full_like(grid, 1.0 / grid[0].size), where=total > 0.0)


def drift(grids: tuple[np.ndarray, ...], offset: np.ndarray, area: np.ndarray, velocity: np.ndarray,
          dt_s: float) -> None:
    """Move the maps ``grids`` (each (N, G, G), in place) with ``velocity`` (N, 2) for ``dt_s``: ``offset`` (N, 2)
    gathers the motion, and each whole cell of it shifts the maps by one cell (what drifts in from beyond the
    area is empty, what drifts out is gone)."""
    offset += velocity * dt_s
    size = cell_size_m(area)
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
    ``belief`` and raises ``searched`` (both (N, G, G), in place) in the footprint by the detection probability of
    an object of size ``size_m`` (N,) with condition factor ``factor`` (N,) (``search.condition_factor`` of the
    reported category). Returns the belief removed per search (N,), the probability this look detects the victim
    under the crew's model."""
    n, grid = belief.shape[0], coverage.GRID_SIZE
    size = cell_size_m(area)
    half_width = search.footprint_half_width_m(altitude_m, zoom)
    reach = int(np.max(half_width[:, None] / size) + 0.5) + 1  # cells from the drone's to a footprint cell's
    k = min(2 * reach + 1, grid)
    water = drone_ne - offset - area[:, 0::2]  # the drone over the map's (unmoved) cells, metres from the corner
    own = np.clip(np.floor(water / size), 0, grid - 1)
    first = np.clip(own - reach, 0, grid - k).astype(np.int64)  # the K x K window, kept inside the grid
    rows = first[:, 0:1, None] + np.arange(k)[None, :, None]  # (N, K, 1)
    cols = first[:, 1:2, None] + np.arange(k)[None, None, :]  # (N, 1, K)
    centres = np.stack(np.broadcast_arrays((rows + 0.5) * size[:, 0, None, None],
                                           (cols + 0.5) * size[:, 1, None, None]), axis=-1)
    centres = centres.reshape(n, k * k, 2) + (area[:, 0::2] + offset)[:, None, :]
    p = search.detection_probability_from_factors(drone_ne, centres, np.repeat(size_m[:, None], k * k, axis=1),
                                                  np.repeat(factor[:, None], k * k, axis=1), altitude_m, zoom,
                                                  intensity)
    index = np.arange(n)[:, None, None], rows, cols
    p = p.reshape(n, k, k)
    before = belief[index]
    belief[index] = before * (1.0 - p)
    searched[index] = 1.0 - (1.0 - searched[index]) * (1.0 - p)
    return (before * p).sum(axis=(1, 2))
