"""PX4's rally points (its "safe points") and where its Return mode goes.

A mixin of :class:`sitl_bridge.px4.autopilot.Px4Autopilot`; the points come from ``sitl_bridge.px4.mission_protocol``
(the RALLY type, kept in dataman's DM_KEY_SAFE_POINTS, at most 32). Read in PX4-Autopilot main at 02e73e3,
``src/modules/navigator/rtl.cpp``:

* ``RTL::on_activation`` → ``setRtlTypeAndDestination``: the destination is chosen once, when Return starts.
  RTL_TYPE 0, PX4's default, is "Return to closest safe point (home or rally point) via direct path"
  (``rtl_params.c``): ``findRtlDestination`` starts from home at its distance from the vehicle, then
  ``findClosestSafePoint`` takes the nearest item that is a MAV_CMD_NAV_RALLY_POINT, lies more than
  MAX_DIST_FROM_HOME_FOR_LAND_APPROACHES (10 m) from home and is more than MIN_DIST_THRESHOLD (2 m) closer than the
  best so far. Other items of a rally upload are stored and never used.
* ``setSafepointAsDestination``: the point's altitude is above mean sea level in MAV_FRAME_GLOBAL and above home in
  MAV_FRAME_GLOBAL_RELATIVE_ALT; ``RtlDirect`` climbs to RTL_RETURN_ALT above it, flies there and lands. At
  02e73e3 the ``_INT`` frames fell through to "RTL: unsupported MAV_FRAME" with an unset position (PX4 issue
  #23715); PX4 pull request #26901, merged into main since, reads them as the frames without ``_INT``, and so does
  the simulator.

RTL_TYPE is not a parameter here: the simulated PX4 always returns as with RTL_TYPE 0 (the other types add mission
landing patterns and reverse missions, which the simulated missions do not have).
"""
from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.mission_items import MissionItem
from sitl_bridge.multirotor import VehicleState

MIN_HOME_DISTANCE_M = 10.0  # MAX_DIST_FROM_HOME_FOR_LAND_APPROACHES: a rally point this close to home is not one
MIN_DIST_THRESHOLD_M = 2.0  # a destination must be this much closer than the best so far to replace it


class Px4RallyPoints:
    """The stored rally points, and the destination of Return (None: home)."""

    rally_points: tuple[MissionItem, ...] = ()
    rtl_destination: tuple[float, float, float] | None = None
    """Where the Return under way goes, in the simulator's NED frame (its down: the rally point's altitude);
    None: home."""

    def load_rally(self, items: list[MissionItem]) -> None:
        """A rally upload (or a clear) arrived: the items that are rally points."""
        self.rally_points = tuple(item for item in items
                                  if item.command == mavlink.MAV_CMD_NAV_RALLY_POINT and item.positional)

    def closest_safe_point(self, state: VehicleState) -> tuple[float, float, float] | None:
        """RTL::findRtlDestination with RTL_TYPE 0: the rally point to return to (north, east, down), or None when
        home is the closest safe point."""
        home_n, home_e, home_d = self.home_ned
        best_m, choice = math.hypot(state.north_m - home_n, state.east_m - home_e), None
        for item in self.rally_points:
            north, east = self.ned_of(item.x, item.y)
            if math.hypot(north - home_n, east - home_e) <= MIN_HOME_DISTANCE_M:
                continue
            distance_m = math.hypot(north - state.north_m, east - state.east_m)
            if distance_m + MIN_DIST_THRESHOLD_M < best_m:
                down = home_d - item.z if item.relative else self.down_of(item.z)
                best_m, choice = distance_m, (north, east, down)
        return choice
