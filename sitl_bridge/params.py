"""The simulated autopilot's parameters: the store, and the PX4 subset (names, defaults, encoding).

PX4 sends integer parameters "bytewise": the int32's four bytes are put in PARAM_VALUE.param_value
(a float field) unchanged, and it announces MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE in
AUTOPILOT_VERSION. We do the same so that clients written for PX4 decode our integers correctly.
ArduPilot sends every parameter as its float value (its table is in :mod:`sitl_bridge.ardupilot.params`);
which encoding a vehicle uses is its autopilot's ``PARAMS_BYTEWISE``.
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

REAL32 = mavlink.MAV_PARAM_TYPE_REAL32
INT32 = mavlink.MAV_PARAM_TYPE_INT32
INT16 = mavlink.MAV_PARAM_TYPE_INT16
INT8 = mavlink.MAV_PARAM_TYPE_INT8
INTEGER_KINDS = (INT8, INT16, INT32)


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: its autopilot's name, type, default, allowed range and meaning."""

    name: str
    kind: int  # REAL32, INT8, INT16 or INT32 (MAV_PARAM_TYPE)
    default: float
    minimum: float
    maximum: float
    doc: str
    allowed: tuple[int, ...] = ()  # for enumerations: the values this simulator implements
    enabled_by: str = ""  # ArduPilot's AP_PARAM_FLAG_ENABLE: hidden (not listed, read or set) while that one is 0


# Defaults follow PX4 v1.14 except where a comment says why not.
PARAM_SPECS: tuple[ParamSpec, ...] = (
    ParamSpec("MIS_TAKEOFF_ALT", REAL32, 2.5, 0.0, 500.0,
              "takeoff altitude above home when NAV_TAKEOFF param7 is NaN (m)"),
    # Mission mode (navigator_params.c, mission_params.c; sitl_bridge.px4.mission)
    ParamSpec("NAV_ACC_RAD", REAL32, 10.0, 0.05, 200.0,
              "mission: horizontal acceptance radius of a waypoint whose param2 does not set one (m)"),
    ParamSpec("NAV_MC_ALT_RAD", REAL32, 0.8, 0.05, 200.0, "mission: vertical acceptance radius of a waypoint (m)"),
    ParamSpec("MIS_DIST_1WP", REAL32, 10000.0, -1.0, 10000.0,
              "mission: warn when the first waypoint is further than this from home (m); <= 0 off"),
    ParamSpec("MIS_YAW_ERR", REAL32, 12.0, 0.0, 90.0,
              "mission: heading error within which a waypoint with a heading (param4) is reached (deg)"),
    ParamSpec("COM_OF_LOSS_T", REAL32, 1.0, 0.0, 60.0, "time without offboard setpoints before the failsafe (s)"),
    ParamSpec("COM_OBL_RC_ACT", INT32, 0, 0, 7,
              "offboard-loss failsafe: 0 position hold (POSCTL), 3 return (RTL), 4 land, 5 hold (AUTO.LOITER)",
              allowed=(0, 3, 4, 5)),
    ParamSpec("COM_DISARM_LAND", REAL32, 2.0, -1.0, 20.0, "auto-disarm this long after landing (s); < 0 never"),
    ParamSpec("COM_DISARM_PRFLT", REAL32, 10.0, -1.0, 60.0,
              "auto-disarm if armed on the ground this long without taking off (s); < 0 never"),
    ParamSpec("MPC_XY_CRUISE", REAL32, 5.0, 0.5, 20.0, "horizontal cruise speed in auto modes such as RTL (m/s)"),
    ParamSpec("MPC_XY_VEL_MAX", REAL32, 12.0, 0.5, 20.0, "horizontal speed limit, also for offboard setpoints (m/s)"),
    ParamSpec("MPC_Z_VEL_MAX_UP", REAL32, 3.0, 0.5, 8.0, "climb speed limit (m/s)"),
    ParamSpec("MPC_Z_VEL_MAX_DN", REAL32, 1.5, 0.5, 4.0, "descent speed limit (m/s)"),
    ParamSpec("MPC_TKO_SPEED", REAL32, 1.5, 0.6, 5.0, "takeoff climb speed (m/s)"),
    ParamSpec("MPC_LAND_SPEED", REAL32, 0.7, 0.6, 3.0, "final landing descent speed (m/s)"),
    ParamSpec("MPC_Z_V_AUTO_DN", REAL32, 1.5, 0.5, 4.0, "auto-mode descent speed above MPC_LAND_ALT1 (m/s)"),
    ParamSpec("MPC_LAND_ALT1", REAL32, 10.0, 0.0, 122.0, "below this altitude landing starts to slow down (m)"),
    ParamSpec("MPC_LAND_ALT2", REAL32, 5.0, 0.0, 122.0, "below this altitude landing descends at MPC_LAND_SPEED (m)"),
    ParamSpec("MPC_YAWRAUTO_MAX", REAL32, 45.0, 5.0, 360.0,
              "yaw rate limit of PX4's auto flight tasks (deg/s; held headings here turn at the airframe's rate)"),
    ParamSpec("MC_YAWRATE_MAX", REAL32, 200.0, 0.0, 1800.0,
              "the attitude controller's yaw rate limit (deg/s): the one an offboard yaw-rate setpoint meets"),
    ParamSpec("MC_ORBIT_RAD_MAX", REAL32, 1000.0, 1.0, 10000.0, "largest radius DO_ORBIT accepts (m)"),
    ParamSpec("MC_ORBIT_YAW_MOD", INT32, 0, 0, 4,
              "orbit heading when DO_ORBIT leaves it unset: 0 facing the centre, 1 the initial heading, "
              "2 uncontrolled, 3 along the tangent, 4 the pilot's"),
    ParamSpec("GF_ACTION", INT32, 2, 0, 5,
              "geofence breach action: 0 none, 1 warning, 2 hold, 3 return (RTL), 5 land", allowed=(0, 1, 2, 3, 5)),
    ParamSpec("GF_MAX_HOR_DIST", REAL32, 0.0, 0.0, 10000.0,
              "geofence: largest horizontal distance from home (m); 0 off"),
    ParamSpec("GF_MAX_VER_DIST", REAL32, 0.0, 0.0, 10000.0, "geofence: largest altitude above home (m); 0 off"),
    # PX4 returns at 60 m; the simulated missions fly low over the sea, so 30 m keeps RTLs short.
    ParamSpec("RTL_RETURN_ALT", REAL32, 30.0, 0.0, 150.0, "RTL climbs to at least this altitude above home (m)"),
    # The battery thresholds' defaults and bounds are PX4's (src/lib/battery/battery_params.c, @min / @max, as the
    # generated parameter file has them: BAT_CRIT_THR and BAT_EMERGEN_THR go up to 0.5).
    ParamSpec("BAT_LOW_THR", REAL32, 0.15, 0.12, 0.5, "battery fraction below which PX4 warns (Low battery)"),
    ParamSpec("BAT_CRIT_THR", REAL32, 0.07, 0.05, 0.5,
              "battery fraction below which the critical level's COM_LOW_BAT_ACT action runs"),
    ParamSpec("BAT_EMERGEN_THR", REAL32, 0.05, 0.03, 0.5,
              "battery fraction below which the emergency level's COM_LOW_BAT_ACT action runs"),
    ParamSpec("COM_LOW_BAT_ACT", INT32, 0, 0, 3,
              "battery failsafe: 0 warning only (PX4's default), 2 land, 3 return at critical, land at emergency",
              allowed=(0, 2, 3)),
    ParamSpec("COM_FAIL_ACT_T", REAL32, 5.0, 0.0, 25.0,
              "hold this long before a geofence or battery Return / Land (s); a mode switch meanwhile cancels it"),
    ParamSpec("MAV_SYS_ID", INT32, 1, 1, 250,
              "this vehicle's MAVLink system id, read once at boot (mavlink_main.cpp: PX4 does not allow it to change "
              "during operation): a PARAM_SET takes effect after a reboot"),
    ParamSpec("SYS_AUTOSTART", INT32, 10016, 0, 9999999, "airframe id (10016: the SITL quadrotor)"),
    # Non-zero calibration ids: some ground stations judge sensors "calibrated" from these.
    ParamSpec("CAL_GYRO0_ID", INT32, 1311244, 0, 2**31 - 1, "gyro calibration id (non-zero = calibrated)"),
    ParamSpec("CAL_ACC0_ID", INT32, 1311244, 0, 2**31 - 1, "accelerometer calibration id (non-zero = calibrated)"),
    ParamSpec("CAL_MAG0_ID", INT32, 197388, 0, 2**31 - 1, "magnetometer calibration id (non-zero = calibrated)"),
)



def encode_bytewise(value: float, kind: int) -> float:
    """The float that carries ``value`` in PARAM_VALUE / PARAM_SET (int32 bytes reinterpreted)."""
    if kind in INTEGER_KINDS:
        return struct.unpack("<f", struct.pack("<i", int(value)))[0]
    return float(value)


def decode_bytewise(wire_value: float, kind: int) -> float:
    """Inverse of :func:`encode_bytewise`."""
    if kind in INTEGER_KINDS:
        return float(struct.unpack("<i", struct.pack("<f", wire_value))[0])
    return float(wire_value)


def decode_float(wire_value: float, kind: int) -> float:
    """A PARAM_SET value as ArduPilot reads it (AP_Param::set_float): integers get 0.01 added, then truncated,
    so that 2.9999 sent for 3 stores 3."""
    if kind in INTEGER_KINDS and math.isfinite(wire_value):
        return float(int(wire_value + 0.01))
    return float(wire_value)


class ParameterStore:
    """Values by name, in a fixed order (the PARAM_VALUE index), with validation on set."""

    def __init__(self, overrides: dict[str, float] | None = None, specs: tuple[ParamSpec, ...] = PARAM_SPECS):
        """``specs``: the personality's table (PX4's by default)."""
        self.specs = {spec.name: spec for spec in specs}
        self._values = {spec.name: float(spec.default) for spec in specs}
        for name, value in (overrides or {}).items():  # hidden ones too: the order of overrides must not matter
            error = self._check_value(name, value)
            if error:
                raise ValueError(error)
            self._values[name] = float(value)

    def __getitem__(self, name: str) -> float:
        """The stored value, hidden or not (the autopilot's own code reads them all)."""
        return self._values[name]

    def __len__(self) -> int:
        return len(self.names)

    @property
    def names(self) -> list[str]:
        """The visible parameters in table order: what PARAM_REQUEST_LIST sends and param_index counts."""
        return [name for name in self.specs if self.visible(name)]

    def visible(self, name: str) -> bool:
        """Known, and not hidden by a zero enable parameter (ArduPilot's BATT_MONITOR 0 hides BATT_*)."""
        spec = self.specs.get(name)
        return spec is not None and (not spec.enabled_by or self._values[spec.enabled_by] != 0)

    def check(self, name: str, value: float) -> str | None:
        """Why ``value`` cannot be stored in ``name``, or None if it can."""
        spec = self.specs.get(name)
        if spec is not None and not self.visible(name):
            return f"{name} is hidden while {spec.enabled_by} is 0"
        return self._check_value(name, value)

    def _check_value(self, name: str, value: float) -> str | None:
        spec = self.specs.get(name)
        if spec is None:
            return f"unknown parameter {name!r}"
        if not math.isfinite(value):
            return f"{name}: value must be finite, got {value}"
        if not spec.minimum <= value <= spec.maximum:
            return f"{name}: {value:g} is outside [{spec.minimum:g}, {spec.maximum:g}]"
        if spec.kind in INTEGER_KINDS and value != int(value):
            return f"{name}: must be an integer, got {value:g}"
        if spec.allowed and int(value) not in spec.allowed:
            return f"{name}: {int(value)} is not implemented here (allowed: {', '.join(map(str, spec.allowed))})"
        return None

    def set(self, name: str, value: float) -> str | None:
        """Store a value; returns the reason it was refused (value unchanged), or None."""
        error = self.check(name, value)
        if error is None:
            self._values[name] = float(value)
        return error

    def index(self, name: str) -> int:
        return self.names.index(name)
