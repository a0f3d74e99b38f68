"""Uploaded fence areas: the inclusion and exclusion polygons and circles both autopilots take as the FENCE type.

PX4 (``sitl_bridge.px4.geofence``) and ArduCopter (``sitl_bridge.ardupilot.polyfence``) store the same items
(MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION/EXCLUSION, one item a vertex, param1 the vertex count;
MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION/EXCLUSION, param1 the radius; MAV_CMD_NAV_FENCE_RETURN_POINT) and test a point
against them alike: a circle by its distance from the centre, a polygon by the crossing-number test (PNPOLY: PX4's
``Geofence::insidePolygon``, ArduPilot's ``Polygon_outside``). They differ in what they do with the areas; this
module only reads the items into areas in the simulator's north/east frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.mission_items import MissionItem

INCLUSIONS = (mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION)
CIRCLES = (mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION)
POLYGON_VERTICES = (mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                    mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION)


@dataclass(frozen=True)
class FenceArea:
    """One uploaded area: a polygon (vertices, north/east m) or a circle (centre and radius), to stay in or out of."""

    inclusion: bool
    vertices: tuple[tuple[float, float], ...] = ()
    centre: tuple[float, float] | None = None
    radius_m: float = 0.0

    def contains(self, north: float, east: float) -> bool:
        if self.centre is not None:  # PX4's Geofence::insideCircle; ArduPilot's differs only on the circle itself
            return (north - self.centre[0]) ** 2 + (east - self.centre[1]) ** 2 < self.radius_m ** 2
        inside, j = False, len(self.vertices) - 1  # PNPOLY, north as latitude, east as longitude
        for i, (n_i, e_i) in enumerate(self.vertices):
            n_j, e_j = self.vertices[j]
            if (e_i >= east) != (e_j >= east) and north <= (n_j - n_i) * (east - e_i) / (e_j - e_i) + n_i:
                inside = not inside
            j = i
        return inside

    def passes(self, north: float, east: float) -> bool:
        """Inside an inclusion, outside an exclusion."""
        return self.contains(north, east) == self.inclusion

    def edge_distance_m(self, north: float, east: float) -> float:
        """How far the point is from the area's boundary (m), whichever side it is on."""
        if self.centre is not None:
            return abs(math.hypot(north - self.centre[0], east - self.centre[1]) - self.radius_m)
        corners = self.vertices
        return min(_segment_distance((north, east), corners[i - 1], corners[i]) for i in range(len(corners)))


def _segment_distance(point: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> float:
    """Vector2f::closest_distance_between_line_and_point: the distance from ``point`` to the segment a-b."""
    dn, de = b[0] - a[0], b[1] - a[1]
    length_sq = dn * dn + de * de
    t = 0.0 if length_sq == 0.0 else min(1.0, max(0.0, ((point[0] - a[0]) * dn + (point[1] - a[1]) * de) / length_sq))
    return math.hypot(point[0] - a[0] - t * dn, point[1] - a[1] - t * de)


def fence_areas(items: list[MissionItem], ned_of: Callable[[float, float], tuple[float, float]]) -> list[FenceArea]:
    """The areas of a stored fence in the order uploaded: a circle per circle item, a polygon per run of param1
    vertices (the first vertex's count); return points are not areas. ``ned_of(lat, lon)`` places a vertex."""
    areas, index = [], 0
    while index < len(items):
        item = items[index]
        inclusion = item.command in INCLUSIONS
        if item.command in CIRCLES:
            areas.append(FenceArea(inclusion, centre=ned_of(item.x, item.y), radius_m=item.params[0]))
            index += 1
        elif item.command in POLYGON_VERTICES:
            corners = items[index:index + int(item.params[0] + 0.5)]
            areas.append(FenceArea(inclusion, vertices=tuple(ned_of(c.x, c.y) for c in corners)))
            index += max(len(corners), 1)
        else:
            index += 1
    return areas
