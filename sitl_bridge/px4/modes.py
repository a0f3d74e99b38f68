"""PX4 flight modes as they appear on the wire.

PX4 packs its mode into HEARTBEAT.custom_mode as ``main_mode << 16 | sub_mode << 24`` and accepts
mode changes as MAV_CMD_DO_SET_MODE with param1 = base mode (CUSTOM_MODE_ENABLED set),
param2 = main mode, param3 = sub mode. Only the modes this simulator flies are listed.
"""
from __future__ import annotations

import enum

from pymavlink.dialects.v20 import common as mavlink

# PX4 main modes (px4_custom_mode.h)
MAIN_POSCTL = 3
MAIN_AUTO = 4
MAIN_OFFBOARD = 6
# PX4 AUTO sub modes
SUB_AUTO_TAKEOFF = 2
SUB_AUTO_LOITER = 3
SUB_AUTO_MISSION = 4
SUB_AUTO_RTL = 5
SUB_AUTO_LAND = 6
# PX4 POSCTL sub modes
SUB_POSCTL_ORBIT = 1


class FlightMode(enum.Enum):
    """The emulated modes, valued by their PX4 (main, sub) pair."""

    HOLD = (MAIN_AUTO, SUB_AUTO_LOITER)
    TAKEOFF = (MAIN_AUTO, SUB_AUTO_TAKEOFF)
    MISSION = (MAIN_AUTO, SUB_AUTO_MISSION)
    OFFBOARD = (MAIN_OFFBOARD, 0)
    RTL = (MAIN_AUTO, SUB_AUTO_RTL)
    LAND = (MAIN_AUTO, SUB_AUTO_LAND)
    POSCTL = (MAIN_POSCTL, 0)
    ORBIT = (MAIN_POSCTL, SUB_POSCTL_ORBIT)  # entered by MAV_CMD_DO_ORBIT only

    @property
    def custom_mode(self) -> int:
        """HEARTBEAT.custom_mode for this mode."""
        main, sub = self.value
        return (main << 16) | (sub << 24)

    @property
    def is_auto(self) -> bool:
        return self.value[0] == MAIN_AUTO

    @classmethod
    def from_custom_mode(cls, custom_mode: int) -> "FlightMode | None":
        """Decode HEARTBEAT.custom_mode; None for a PX4 mode that is not emulated."""
        main, sub = (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
        return cls((main, sub)) if (main, sub) == cls.ORBIT.value else cls.from_main_sub(main, sub)

    @classmethod
    def from_main_sub(cls, main: int, sub: int) -> "FlightMode | None":
        """Decode a DO_SET_MODE request. POSCTL and OFFBOARD ignore the sub mode, as PX4 does (so Orbit, which only
        DO_ORBIT enters, cannot be asked for)."""
        for mode in cls:
            mode_main, mode_sub = mode.value
            if mode is not cls.ORBIT and mode_main == main and (mode_sub == sub
                                                                 or main in (MAIN_POSCTL, MAIN_OFFBOARD)):
                return mode
        return None


def base_mode(mode: FlightMode, armed: bool) -> int:
    """HEARTBEAT.base_mode as PX4 fills it for a multirotor in ``mode``."""
    flags = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
    flags |= mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
    if mode.is_auto:
        flags |= mavlink.MAV_MODE_FLAG_AUTO_ENABLED
    if mode in (FlightMode.POSCTL, FlightMode.ORBIT):
        flags |= mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
    if armed:
        flags |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    return flags
