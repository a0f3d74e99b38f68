"""Mission items as both autopilots store them, and as a download sends them back.

The two mission protocols (``sitl_bridge.px4.mission_protocol``, ``sitl_bridge.ardupilot.mission_protocol``) differ
in nearly every rule of the transfer, but store the same thing: a command, four parameters and a position (or
param5-7), and send it back in the ``_INT`` or float form (PX4's ``format_mavlink_mission_item``; ArduPilot's
``AP_Mission::mission_cmd_to_mavlink_int``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

MISSION, FENCE, RALLY = mavlink.MAV_MISSION_TYPE_MISSION, mavlink.MAV_MISSION_TYPE_FENCE, mavlink.MAV_MISSION_TYPE_RALLY
ABSOLUTE_FRAMES = (mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_INT)
RELATIVE_FRAMES = (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)


@dataclass(frozen=True)
class MissionItem:
    """One stored mission item: its command, param1-4, and a position (degrees, metres) or param5-7."""

    command: int
    params: tuple[float, float, float, float]
    x: float
    """Latitude (degrees) for a positional item, else param5."""
    y: float
    """Longitude (degrees) for a positional item, else param6."""
    z: float
    """Altitude (m: above home when ``relative``, else above mean sea level) or param7."""
    positional: bool
    relative: bool = False
    autocontinue: bool = True


def item_message(item: MissionItem, seq: int, current: bool, target: tuple[int, int], as_int: bool,
                 mission_type: int = MISSION) -> mavlink.MAVLink_message:
    """The item as PX4's format_mavlink_mission_item sends it in a download."""
    if item.positional:
        frame = RELATIVE_FRAMES[as_int] if item.relative else ABSOLUTE_FRAMES[as_int]
    else:
        frame = mavlink.MAV_FRAME_MISSION
    x, y = item.x, item.y
    if as_int:
        x, y = (_int32(x * 1e7), _int32(y * 1e7)) if item.positional else (_int32(x), _int32(y))
        return mavlink.MAVLink_mission_item_int_message(*target, seq, frame, item.command, int(current),
                                                        int(item.autocontinue), *item.params, x, y, item.z,
                                                        mission_type)
    return mavlink.MAVLink_mission_item_message(*target, seq, frame, item.command, int(current),
                                                int(item.autocontinue), *item.params, x, y, item.z, mission_type)


def _int32(value: float) -> int:
    """A float as MISSION_ITEM_INT's int32 x / y (a float item's NaN or huge param5/6 cannot go out as one)."""
    return int(round(min(max(value, -2.0**31), 2.0**31 - 1))) if math.isfinite(value) else 0
