"""ArduCopter's rally points: the RALLY mission type, and RTL to the closest rally point.

Read in ArduPilot master at 9070097:

* ``libraries/GCS_MAVLink/MissionItemProtocol_Rally.cpp``: only MAV_CMD_NAV_RALLY_POINT (else UNSUPPORTED); the
  latitude and longitude checked (INVALID_PARAM5_X / 6_Y), the altitude a whole number of metres in an int16
  (INVALID_PARAM7 outside); frames GLOBAL(_INT) (above mean sea level) and GLOBAL_RELATIVE_ALT(_INT) (above home),
  GLOBAL_TERRAIN_ALT(_INT) too where terrain data is built in, else UNSUPPORTED_FRAME. The points are written as
  they arrive: MISSION_COUNT truncates the stored list to the count (``truncate``), each item replaces its index or
  is appended (``replace_item``, ``append_item``), so a refused item leaves the points before it stored. No text
  when complete; "Rally upload timeout". A download sends frame GLOBAL_RELATIVE_ALT or GLOBAL, the altitude in
  metres, param1-4 0; a point at latitude and longitude 0 is not one (INVALID_SEQUENCE, never flown to).
* ``libraries/AP_Rally/AP_Rally.cpp``: the capacity is the rally storage's bytes / 15 (46 in SITL's layout);
  RALLY_LIMIT_KM (Copter: 0.3) and RALLY_INCL_HOME (Copter: 1). ``calc_best_rally_or_home_location``: the nearest
  rally point (``find_nearest_rally_point``), unless it is more than RALLY_LIMIT_KM away (0: no limit); with
  RALLY_INCL_HOME, only if it is closer than home.
* ``ArduCopter/mode_rtl.cpp`` ``compute_return_target``: RTL returns to that point, at least at its altitude (above
  home, never below 0) and RTL_ALT, the cone slope counted from the distance to it, then lands there (AUTO's
  RETURN_TO_LAUNCH too: it runs RTL).

The rally terrain frames are refused here (no terrain data is simulated), and RALLY_TOTAL, the parameter ArduPilot
keeps the count in, is not one here.
"""
from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.ardupilot.item_protocol import ACCEPTED, ItemProtocol, Upload
from sitl_bridge.mission_items import ABSOLUTE_FRAMES, RALLY, RELATIVE_FRAMES, MissionItem
from sitl_bridge.multirotor import VehicleState

STORAGE_BYTES = 690  # StorageRally areas of a 15-area layout (90 + 300 + 300), SITL's


def parse_rally_point(msg: mavlink.MAVLink_message) -> MissionItem | int:
    """convert_MISSION_ITEM_INT_to_RallyLocation, or the MAV_MISSION_RESULT refusing the item."""
    if msg.command != mavlink.MAV_CMD_NAV_RALLY_POINT:
        return mavlink.MAV_MISSION_UNSUPPORTED
    scale = 1.0 if msg.get_type() == "MISSION_ITEM" else 1e-7
    lat, lon = msg.x * scale, msg.y * scale
    if not (math.isfinite(lat) and abs(lat) <= 90.0):
        return mavlink.MAV_MISSION_INVALID_PARAM5_X
    if not (math.isfinite(lon) and abs(lon) <= 180.0):
        return mavlink.MAV_MISSION_INVALID_PARAM6_Y
    if not (math.isfinite(msg.z) and -32768 <= msg.z <= 32767):  # a NaN is refused here: ArduPilot's check passes it
        return mavlink.MAV_MISSION_INVALID_PARAM7
    if msg.frame not in ABSOLUTE_FRAMES + RELATIVE_FRAMES:
        return mavlink.MAV_MISSION_UNSUPPORTED_FRAME
    if scale == 1.0:  # the MISSION_ITEM's degrees went into MISSION_ITEM_INT's integers
        lat, lon = int(msg.x * 1e7) * 1e-7, int(msg.y * 1e7) * 1e-7
    return MissionItem(msg.command, (0.0, 0.0, 0.0, 0.0), lat, lon, float(int(msg.z)), positional=True,
                       relative=msg.frame in RELATIVE_FRAMES, autocontinue=False)


class CopterRallyTransfer(ItemProtocol):
    """ArduPilot's RALLY type: ``items`` is the rally storage, handed to the autopilot after every change (the points
    are written one by one)."""

    MISSION_TYPE = RALLY
    MAX_ITEMS = STORAGE_BYTES // 15  # sizeof(RallyLocation)
    TIMEOUT_TEXT = "Rally upload timeout"

    def begin(self, count: int) -> None:
        if count < len(self.items):  # AP_Rally::truncate: "we never make the space larger this way"
            self.items = self.items[:count]
            self._on_change(self.items)

    def take(self, seq: int, msg: mavlink.MAVLink_message, upload: Upload) -> int:
        point = parse_rally_point(msg)
        if isinstance(point, int):
            return point
        if seq < len(self.items):
            self.items[seq] = point
        elif seq == len(self.items):
            self.items.append(point)
        else:
            return mavlink.MAV_MISSION_ERROR
        self._on_change(self.items)
        return ACCEPTED

    def complete(self, upload: Upload) -> int:
        return ACCEPTED

    def get_item(self, seq: int) -> tuple[MissionItem, int] | int:
        if seq >= len(self.items) or self.items[seq].x == self.items[seq].y == 0.0:
            return mavlink.MAV_MISSION_INVALID_SEQUENCE
        point = self.items[seq]
        return point, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT if point.relative else mavlink.MAV_FRAME_GLOBAL


class CopterRally:
    """AP_Rally's choice of where RTL goes (a mixin of :class:`sitl_bridge.ardupilot.autopilot.ArduCopter`)."""

    rally_points: tuple[MissionItem, ...] = ()

    def load_rally(self, points: list[MissionItem]) -> None:
        """The rally storage changed."""
        self.rally_points = tuple(points)

    def rtl_return_target(self, state: VehicleState) -> tuple[float, float, float]:
        """AP_Rally::calc_best_rally_or_home_location: (north, east, altitude above home) of the rally point RTL
        returns to, or home's (altitude 0)."""
        home_n, home_e, home_d = self.home_ned
        nearest, nearest_m = None, -1.0
        for point in self.rally_points:
            if point.x == point.y == 0.0:  # get_rally_point_with_index's sanity check
                continue
            north, east = self.ned_of(point.x, point.y)
            distance_m = math.hypot(north - state.north_m, east - state.east_m)
            if nearest is None or distance_m < nearest_m:
                nearest, nearest_m = point, distance_m
        limit_km = self.params["RALLY_LIMIT_KM"]
        if nearest is None or (limit_km > 0 and nearest_m > limit_km * 1000.0):
            return home_n, home_e, 0.0
        home_m = math.hypot(home_n - state.north_m, home_e - state.east_m)
        if int(self.params["RALLY_INCL_HOME"]) and not nearest_m < home_m:
            return home_n, home_e, 0.0
        north, east = self.ned_of(nearest.x, nearest.y)
        alt = nearest.z if nearest.relative else home_d - self.down_of(nearest.z)
        return north, east, alt
