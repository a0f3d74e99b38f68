"""The safety shield of SarSearch-v1: a velocity filter that keeps the drone out of the charted danger zones and
inside the geofence, whoever commands it (a learned policy, a scripted searcher).

The training environment applies it to every velocity command before flying it, and the flight pilot to every
command it hands the runner, so what was trained is what flies; it does the runner's geofence guard's job
(``autonomy.runner.RunnerConfig``: 20 m margin, 2 s look-ahead) before the runner sees the command, with the same
margin and look-ahead, and adds the danger zones. Per command, for the position ``LOOKAHEAD_S`` ahead:

* **danger zones** (circles inflated by ``ZONE_MARGIN_M``): the part of the velocity towards a zone's centre is
  removed when the point ahead lies inside the inflated circle, so the drone slides round it; inside the inflated
  circle already, it is also sent out at ``RECOVERY_MPS``;
* **geofence** (shrunk by ``FENCE_MARGIN_M``): a component that would carry the point ahead beyond the margin is
  removed; beyond the margin already, the drone is sent back in at ``RECOVERY_MPS`` along that axis.
"""
from __future__ import annotations

import numpy as np

LOOKAHEAD_S = 2.0
FENCE_MARGIN_M = 20.0
ZONE_MARGIN_M = 10.0
RECOVERY_MPS = 1.0


def shield_velocity(position: np.ndarray, velocity: np.ndarray, obstacles: np.ndarray, obstacle_valid: np.ndarray,
                    fence: np.ndarray) -> np.ndarray:
    """(N, 2) the velocity commands (m/s, north and east) the drones at ``position`` (N, 2) may fly, given the
    danger zones (N, O, 3: north, east, radius; ``obstacle_valid`` (N, O)) and the fence rectangles (N, 4)."""
    v = np.array(velocity, dtype=np.float64, copy=True)
    for k in range(obstacles.shape[1]):
        to_centre = obstacles[:, k, :2] - position
        distance = np.hypot(*to_centre.T)
        inward = to_centre / np.maximum(distance, 1e-9)[:, None]
        radius = obstacles[:, k, 2] + ZONE_MARGIN_M
        ahead = position + v * LOOKAHEAD_S
        closing = np.einsum("ij,ij->i", v, inward)
        threatened = obstacle_valid[:, k] & (np.hypot(*(ahead - obstacles[:, k, :2]).T) < radius) & (closing > 0.0)
        v[threatened] -= closing[threatened, None] * inward[threatened]
        inside = obstacle_valid[:, k] & (distance < radius)
        v[inside] -= RECOVERY_MPS * inward[inside]
    for axis in (0, 1):
        low, high = fence[:, 2 * axis] + FENCE_MARGIN_M, fence[:, 2 * axis + 1] - FENCE_MARGIN_M
        here, ahead = position[:, axis], position[:, axis] + v[:, axis] * LOOKAHEAD_S
        v[:, axis] = np.where((ahead > high) & (v[:, axis] > 0.0), 0.0, v[:, axis])
        v[:, axis] = np.where((ahead < low) & (v[:, axis] < 0.0), 0.0, v[:, axis])
        v[:, axis] = np.where(here > high, np.minimum(v[:, axis], -RECOVERY_MPS), v[:, axis])
        v[:, axis] = np.where(here < low, np.maximum(v[:, axis], RECOVERY_MPS), v[:, axis])
    return v
