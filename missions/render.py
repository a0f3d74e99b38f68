"""Drawing a search as an RGB image with OpenCV (the environment's ``render()``, mission replay images and videos)."""
from __future__ import annotations

from typing import Sequence

import cv2
import numpy as np

from missions import search
from missions.goals import GOAL_NAMES
from missions.scenario import CATEGORIES
from missions.search_state_v0 import SearchState

SIZE_PX = 512
# BGR-free: colours are RGB because the image is returned as RGB.
CATEGORY_COLOURS = {"person": (255, 60, 60), "boat": (240, 240, 240), "life_jacket": (255, 150, 0),
                    "debris": (140, 100, 60), "floating_object": (255, 230, 80), "swimmer": (255, 90, 200)}
SEA = np.array([20, 60, 110], dtype=np.uint8)
COVERED = np.array([50, 110, 150], dtype=np.uint8)


def render_search(core: SearchState, index: int, path: Sequence[tuple[float, float]], zoom: float) -> np.ndarray:
    """(512, 512, 3) uint8 RGB of search ``index``: coverage, danger zones, objects (victim ringed), datum, the
    path flown, the camera footprint (at ``zoom``) and the current goal."""
    area = core.scen.area[index]

    def pixel(north: float, east: float) -> tuple[int, int]:
        x = (east - area[2]) / (area[3] - area[2]) * (SIZE_PX - 1)
        y = (area[1] - north) / (area[1] - area[0]) * (SIZE_PX - 1)  # north up
        return int(round(x)), int(round(y))

    metres_to_px = (SIZE_PX - 1) / max(area[1] - area[0], area[3] - area[2])
    covered = core.coverage[index][::-1] > 0.5  # row 0 is the southernmost: flip so north is up
    cells = np.where(covered[..., None], COVERED, SEA).astype(np.uint8)
    image = np.ascontiguousarray(cv2.resize(cells, (SIZE_PX, SIZE_PX), interpolation=cv2.INTER_NEAREST))
    for (north, east, radius), valid in zip(core.scen.obstacles[index], core.scen.obstacle_valid[index]):
        if valid:
            cv2.circle(image, pixel(north, east), max(2, int(radius * metres_to_px)), (200, 40, 40), -1)
    datum = pixel(*core.scen.datum[index])
    cv2.circle(image, datum, max(3, int(core.scen.datum_sigma[index] * metres_to_px)), (200, 200, 200), 1)
    cv2.drawMarker(image, datum, (220, 220, 220), cv2.MARKER_CROSS, 12, 1)
    for t, (position, category, valid) in enumerate(zip(core.targets[index], core.scen.target_category[index],
                                                          core.scen.target_valid[index])):
        if valid:
            colour = CATEGORY_COLOURS[CATEGORIES[category]]
            cv2.circle(image, pixel(*position), 4, colour, -1)
            if t == core.scen.primary_index[index]:
                cv2.circle(image, pixel(*position), 9, colour, 2)
    if len(path) > 1:
        points = np.array([pixel(n, e) for n, e in path], dtype=np.int32)
        cv2.polylines(image, [points], False, (120, 255, 120), 1, cv2.LINE_AA)
    north, east = core.position[index]
    half = float(search.footprint_half_width_m(core.flight.altitude_m, zoom))
    cv2.rectangle(image, pixel(north + half, east - half), pixel(north - half, east + half), (120, 255, 120), 1)
    cv2.circle(image, pixel(north, east), 4, (120, 255, 120), -1)
    if core.goal[index] >= 0:
        cv2.drawMarker(image, pixel(*core.goal_point[index]), (255, 255, 0), cv2.MARKER_DIAMOND, 14, 2)
        cv2.putText(image, GOAL_NAMES[core.goal[index]], (8, SIZE_PX - 10), cv2.FONT_HERSHEY_SIMPLEX, 0.45,
                    (255, 255, 0), 1, cv2.LINE_AA)
    coverage = core.covered_cells[index] / core.coverage[index].size
    cv2.putText(image, f"step {int(core.steps[index])}  coverage {coverage:.0%}",
                (8, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
    return image
