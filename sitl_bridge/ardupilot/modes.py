"""ArduCopter flight modes as they appear on the wire, and what each allows.

ArduPilot puts the mode number itself in HEARTBEAT.custom_mode (GCS_Copter::custom_mode returns
``flightmode->mode_number()``); the numbers are ArduCopter's ``Mode::Number`` (ArduCopter/mode.h) and are what
pymavlink's ``mavutil.mode_mapping_acm`` decodes. A mode change is MAV_CMD_DO_SET_MODE with param1 having
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED and param2 = the number, or the SET_MODE message (base_mode, custom_mode).

Only the modes this simulator flies are listed; the flags below are ArduCopter's ``requires_GPS()``,
``allows_arming()`` (from a ground station), ``is_autopilot()`` and ``has_user_takeoff()`` of each mode class.
"""
from __future__ import annotations

import enum

from pymavlink.dialects.v20 import common as mavlink


class CopterMode(enum.IntEnum):
    """The emulated ArduCopter modes, valued by their ``Mode::Number``."""

    STABILIZE = 0
    AUTO = 3
    GUIDED = 4
    LOITER = 5
    RTL = 6
    LAND = 9
    BRAKE = 17

    @property
    def requires_gps(self) -> bool:
        """Entering it when armed needs a position estimate ("Mode change to X failed: requires position")."""
        return self in (CopterMode.GUIDED, CopterMode.LOITER, CopterMode.RTL, CopterMode.BRAKE, CopterMode.AUTO)

    @property
    def allows_arming(self) -> bool:
        """Arming in this mode is allowed from a ground station (else "Arm: Mode not armable"; AUTO: only
        with AUTO_OPTIONS bit 0, which the autopilot checks)."""
        return self in (CopterMode.STABILIZE, CopterMode.GUIDED, CopterMode.LOITER)

    @property
    def is_autopilot(self) -> bool:
        """An autopilot mode (not pilot controlled): FS_OPTIONS bit 4 keeps pilot modes going on GCS failsafe."""
        return self in (CopterMode.GUIDED, CopterMode.RTL, CopterMode.LAND, CopterMode.AUTO)

    @property
    def has_user_takeoff(self) -> bool:
        """MAV_CMD_NAV_TAKEOFF works in this mode (Mode::has_user_takeoff with must_navigate)."""
        return self in (CopterMode.GUIDED, CopterMode.LOITER)

    @property
    def controls_position(self) -> bool:
        """The position controller runs horizontally in this mode (HEARTBEAT's GUIDED_ENABLED flag, in the air)."""
        return self is not CopterMode.STABILIZE


# ArduCopter mode numbers that exist but are not emulated (a DO_SET_MODE to one of these FAILS here, where real
# ArduPilot would switch); any other number is "No such mode".
OTHER_COPTER_MODES = {1: "ACRO", 2: "ALT_HOLD", 7: "CIRCLE", 11: "DRIFT", 13: "SPORT", 14: "FLIP",
                      15: "AUTOTUNE", 16: "POSHOLD", 18: "THROW", 19: "AVOID_ADSB", 20: "GUIDED_NOGPS",
                      21: "SMART_RTL", 22: "FLOWHOLD", 23: "FOLLOW", 24: "ZIGZAG", 25: "SYSTEMID", 26: "AUTOROTATE",
                      27: "AUTO_RTL", 28: "TURTLE"}


def base_mode(mode: CopterMode, armed: bool, airborne: bool) -> int:
    """HEARTBEAT.base_mode as GCS_MAVLINK_Copter::base_mode() fills it: STABILIZE_ENABLED and
    MANUAL_INPUT_ENABLED always, GUIDED_ENABLED while the horizontal position controller is active (here: a
    position-controlled mode in the air), SAFETY_ARMED when armed, and CUSTOM_MODE_ENABLED."""
    flags = mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED | mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
    flags |= mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    if airborne and mode.controls_position:
        flags |= mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
    if armed:
        flags |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    return flags
