"""ArduCopter's FENCE mission type: polygon and circle fences uploaded with the mission item protocol.

Read in ArduPilot master at 9070097: ``libraries/GCS_MAVLink/MissionItemProtocol_Fence.cpp`` and
``libraries/AC_Fence/AC_PolyFence_loader.cpp``:

* ``convert_MISSION_ITEM_INT_to_AC_PolyFenceItem``: frames GLOBAL, GLOBAL_RELATIVE_ALT and GLOBAL_TERRAIN_ALT (and
  their ``_INT`` forms; the altitude is not kept), else UNSUPPORTED_FRAME; the commands inclusion/exclusion polygon
  vertex (param1 the vertex count, over 255 INVALID_PARAM1), inclusion/exclusion circle (param1 the radius) and the
  return point, else UNSUPPORTED. A MISSION_ITEM's latitude/longitude are checked first (INVALID_PARAM5_X / 6_Y,
  ``AP_Mission::convert_MISSION_ITEM_to_MISSION_ITEM_INT``).
* The items are collected and written at once after the last (``complete`` → ``write_fence``):
  ``validate_fence`` refuses a polygon of fewer than 3 vertices ("Invalid vertex count (N)"), a polygon's vertices
  that change type or count ("Received incorrect vertex type ...", "Unexpected vertex count ..."), another item
  before a polygon is complete ("Received incorrect type ..."), a circle whose radius is not positive ("Non-positive
  circle radius"), a second return point ("Multiple return points"), a latitude/longitude out of range ("Bad lat or
  lon"), an unfinished last polygon ("Incorrect item count"); then "Fence validation failed" and ACK ERROR. A fence
  that does not fit the storage (``fence_storage_space_required``) is "Fence exceeds storage size", ERROR.
* Capacity: the fence storage's bytes / 8 (``max_items``): 70 items in SITL's storage layout (560 bytes); timeout
  text "Fence upload timeout"; a download sends frame GLOBAL, altitude 0, param1 the count or radius;
  MISSION_CLEAR_ALL writes an empty fence.
"""
from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.ardupilot.item_protocol import ACCEPTED, ItemProtocol, Upload
from sitl_bridge.fence_areas import CIRCLES, POLYGON_VERTICES
from sitl_bridge.mission_items import ABSOLUTE_FRAMES, FENCE, RELATIVE_FRAMES, MissionItem

STORAGE_BYTES = 560  # StorageFence areas of a 15-area layout (48 + 256 + 256), SITL's
TERRAIN_FRAMES = (mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT, mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT)
RETURN_POINT = mavlink.MAV_CMD_NAV_FENCE_RETURN_POINT


def parse_fence_item(msg: mavlink.MAVLink_message) -> MissionItem | int:
    """An uploaded fence item as ArduPilot stores it (AC_PolyFenceItem: the type, lat/lon in 1e-7 degrees, the
    vertex count as a uint8 or the radius), or the MAV_MISSION_RESULT refusing it."""
    if msg.get_type() == "MISSION_ITEM":  # convert_MISSION_ITEM_to_MISSION_ITEM_INT: fence items have a location
        if not (math.isfinite(msg.x) and abs(msg.x) <= 90.0):
            return mavlink.MAV_MISSION_INVALID_PARAM5_X
        if not (math.isfinite(msg.y) and abs(msg.y) <= 180.0):
            return mavlink.MAV_MISSION_INVALID_PARAM6_Y
        x, y = int(msg.x * 1e7), int(msg.y * 1e7)
    else:
        x, y = msg.x, msg.y
    if msg.frame not in ABSOLUTE_FRAMES + RELATIVE_FRAMES + TERRAIN_FRAMES:
        return mavlink.MAV_MISSION_UNSUPPORTED_FRAME
    param1 = msg.param1
    if msg.command in POLYGON_VERTICES:
        if param1 > 255:
            return mavlink.MAV_MISSION_INVALID_PARAM1
        param1 = float(int(param1)) if math.isfinite(param1) and param1 > 0 else 0.0  # the uint8 vertex_count
    elif msg.command == RETURN_POINT:
        param1 = 0.0
    elif msg.command not in CIRCLES:
        return mavlink.MAV_MISSION_UNSUPPORTED
    return MissionItem(msg.command, (param1, 0.0, 0.0, 0.0), x * 1e-7, y * 1e-7, 0.0, positional=True,
                       autocontinue=False)


def validation_failure(items: list[MissionItem]) -> str | None:
    """AC_PolyFence_loader::validate_fence: the text of the first problem, or None."""
    expecting, remaining, per_polygon, seen_return = None, 0, 0, False
    for item in items:
        if item.command in POLYGON_VERTICES:
            count = int(item.params[0])
            if count < 3:
                return f"Invalid vertex count ({count})"
            if remaining == 0:
                expecting, remaining, per_polygon = item.command, count, count
            elif item.command != expecting:
                return f"Received incorrect vertex type (want={expecting} got={item.command})"
            elif count != per_polygon:
                return f"Unexpected vertex count want={per_polygon} got={count}"
            remaining -= 1
        elif remaining:
            return f"Received incorrect type (want={expecting} got={item.command})"
        elif item.command in CIRCLES and not item.params[0] > 0.0:
            return "Non-positive circle radius"
        elif item.command == RETURN_POINT:
            if seen_return:
                return "Multiple return points"
            seen_return = True
        if not (abs(item.x) <= 90.0 and abs(item.y) <= 180.0):
            return "Bad lat or lon"
    return "Incorrect item count" if remaining else None


def storage_bytes(items: list[MissionItem]) -> int:
    """fence_storage_space_required: a header, then a type byte per fence, a polygon's count and 8 bytes a vertex,
    a circle's radius and centre (12), a return point's place (8)."""
    total, index = 4, 0
    while index < len(items):
        item = items[index]
        if item.command in POLYGON_VERTICES:
            total, index = total + 2 + 8 * int(item.params[0]), index + int(item.params[0])
        else:
            total, index = total + (13 if item.command in CIRCLES else 9), index + 1
    return total


class CopterFenceTransfer(ItemProtocol):
    """ArduPilot's FENCE type: ``items`` is the stored fence, handed to the autopilot
    (``sitl_bridge.ardupilot.polyfence``) when a new one is written or the fence cleared."""

    MISSION_TYPE = FENCE
    MAX_ITEMS = STORAGE_BYTES // 8
    TIMEOUT_TEXT = "Fence upload timeout"

    def item_count(self) -> int:
        return self.upload.count if self.upload is not None else len(self.items)

    def take(self, seq: int, msg: mavlink.MAVLink_message, upload: Upload) -> int:
        item = parse_fence_item(msg)
        if isinstance(item, int):
            return item
        upload.items.append(item)
        return ACCEPTED

    def complete(self, upload: Upload) -> int:
        failure = validation_failure(upload.items)
        if failure is not None:
            self._text(failure, mavlink.MAV_SEVERITY_WARNING)
            self._text("Fence validation failed", mavlink.MAV_SEVERITY_WARNING)
            return mavlink.MAV_MISSION_ERROR
        if storage_bytes(upload.items) > STORAGE_BYTES:
            self._text("Fence exceeds storage size", mavlink.MAV_SEVERITY_WARNING)
            return mavlink.MAV_MISSION_ERROR
        self.items = list(upload.items)
        self._on_change(self.items)
        return ACCEPTED

    def get_item(self, seq: int) -> tuple[MissionItem, int] | int:
        if seq >= len(self.items):
            return mavlink.MAV_MISSION_INVALID_SEQUENCE
        return self.items[seq], mavlink.MAV_FRAME_GLOBAL
