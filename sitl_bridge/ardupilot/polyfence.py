"""ArduCopter's uploaded fences (FENCE_TYPE bit 4, "Inclusion/Exclusion Circles+Polygons"): where they are, whether
the vehicle breaches them, and their pre-arm checks. A mixin of :class:`sitl_bridge.ardupilot.autopilot.ArduCopter`
used by its fence (``sitl_bridge.ardupilot.fence``); the items come from ``sitl_bridge.ardupilot.fence_protocol``.

Read in ArduPilot master at 9070097, ``libraries/AC_Fence/AC_PolyFence_loader.cpp``:

* ``load_from_storage``: the fences are loaded once the EKF has an origin (here: the first GPS fix); before that
  none is present and ``loaded()`` is false.
* ``breached(loc, distance_outside_fence)``: with FENCE_OPTIONS at Copter's default (0, the intersection of the
  inclusion areas) the vehicle is outside when it is outside any inclusion polygon or circle, or inside any
  exclusion polygon or circle (``Polygon_outside``, the crossing-number test; a circle by the distance to its
  centre). The distance outside is what ``Copter::fence_check`` compares with AC_FENCE_GIVE_UP_DISTANCE: inside an
  exclusion polygon, the distance to its nearest edge; outside inclusion polygons, the smallest distance to one of
  their edges; circles by how far past the radius.
* ``AC_Fence::pre_arm_check_polygon``: "Polygon fence(s) invalid" when not loaded, "Polygon fence margin is greater
  than inclusion circle radius" (``check_inclusion_circle_margin``).
"""
from __future__ import annotations

import math

from sitl_bridge.fence_areas import FenceArea, fence_areas
from sitl_bridge.mission_items import MissionItem


class CopterPolyFence:
    """The uploaded inclusion and exclusion polygons and circles of ArduCopter's fence."""

    _stored_areas: tuple[FenceArea, ...] = ()

    def load_polyfence(self, items: list[MissionItem]) -> None:
        """A fence upload (or a clear) was written."""
        self._stored_areas = tuple(fence_areas(items, self.ned_of))

    @property
    def polyfence_areas(self) -> tuple[FenceArea, ...]:
        """The loaded areas; none before the EKF has an origin (AC_PolyFence_loader::load_from_storage)."""
        return self._stored_areas if self.gps_ok else ()

    def polyfence_breach(self, north: float, east: float) -> tuple[bool, float]:
        """AC_PolyFence_loader::breached: (outside the fence, the distance outside it in m; negative inside)."""
        distance, outside_inclusions = -math.inf, 0
        areas = self.polyfence_areas
        polygons = [a for a in areas if a.centre is None and a.inclusion] + [
            a for a in areas if a.centre is None and not a.inclusion]
        for area in polygons:  # inclusion polygons, then exclusion polygons
            edge_m = area.edge_distance_m(north, east)
            inside = area.contains(north, east)
            if area.inclusion and not inside:
                outside_inclusions += 1
                distance = min(distance, edge_m) if distance > 0 else edge_m
            elif not area.inclusion and inside:
                return True, edge_m
            else:
                distance = max(distance, -edge_m)
        circles = [a for a in areas if a.centre is not None and not a.inclusion] + [
            a for a in areas if a.centre is not None and a.inclusion]
        for area in circles:  # exclusion circles, then inclusion circles
            centre_m = math.hypot(north - area.centre[0], east - area.centre[1])
            if area.inclusion:
                distance = max(distance, centre_m - area.radius_m)
                outside_inclusions += centre_m > area.radius_m
            else:
                distance = max(distance, area.radius_m - centre_m)
                if centre_m < area.radius_m:
                    return True, distance
        return outside_inclusions > 0, distance if math.isfinite(distance) else 0.0

    def polyfence_prearm_failure(self) -> str | None:
        """AC_Fence::pre_arm_check_polygon (FENCE_TYPE has the polygon bit)."""
        if not self.gps_ok:
            return "Polygon fence(s) invalid"
        margin = self.params["FENCE_MARGIN"]
        if any(area.inclusion and area.radius_m < margin for area in self.polyfence_areas if area.centre is not None):
            return "Polygon fence margin is greater than inclusion circle radius"
        return None
