"""The ArduCopter parameters the simulated ArduPilot personality implements: ArduPilot's names, types and defaults.

Sources (ArduPilot/ardupilot, read through the search tools; see docs/sitl.md): ArduCopter/Parameters.cpp
(SYSID_MYGCS, RTL_*, FS_GCS_ENABLE, LAND_SPEED*, DISARM_DELAY, GUID_TIMEOUT, FS_GCS_TIMEOUT, FS_OPTIONS),
libraries/AC_WPNav/AC_WPNav.cpp (WPNAV_SPEED 1000, WPNAV_SPEED_UP 250, WPNAV_SPEED_DN 150),
libraries/AC_Fence/AC_Fence.cpp (FENCE_*), libraries/AP_Rally/AP_Rally.cpp (RALLY_LIMIT_KM 0.3 and RALLY_INCL_HOME 1
on Copter),
libraries/AP_BattMonitor/AP_BattMonitor_Params.cpp (BATT_MONITOR with AP_PARAM_FLAG_ENABLE, BATT_LOW_VOLT 10.5 V
on Copter, the others 0 = off) and
libraries/GCS_MAVLink/GCS_MAVLink_Parameters.cpp (SRn_* stream rates: 0 on Copter, so nothing streams until a
ground station asks). Units are ArduPilot's (cm, cm/s, ms) because that is what a client reads and writes.

ArduPilot sends every value as a float (``PARAMS_BYTEWISE`` False) and types integer parameters by their AP_Param
size (INT8/INT16/INT32). Real ArduPilot stores any value a PARAM_SET sends (the @Range is ground-station
metadata); this simulator refuses values outside the range below and echoes the old one.
"""
from __future__ import annotations

from sitl_bridge.params import INT8, INT16, INT32, REAL32, ParamSpec

STREAM_LINKS = 3  # SR0_ .. SR2_: one set per MAVLink link of the vehicle, in link order
STREAM_GROUPS = ("EXT_STAT", "POSITION", "EXTRA1", "EXTRA2", "EXTRA3")

_FAILSAFE_ACTIONS = "0 none, 1 RTL, 2 RTL (the old 'continue mission in Auto'), 5 land, 7 brake or land"
_BATTERY_ACTIONS = "0 warn only, 1 land, 2 RTL, 7 brake or land"
_MONITOR = "BATT_MONITOR"

ARDUPILOT_PARAM_SPECS: tuple[ParamSpec, ...] = (
    ParamSpec("SYSID_THISMAV", INT16, 1, 1, 255,
              "this vehicle's MAVLink system id, read once at boot (GCS::init): a PARAM_SET takes effect after a "
              "reboot"),
    ParamSpec("SYSID_MYGCS", INT16, 255, 1, 255,
              "the ground station's system id: only its HEARTBEATs keep the GCS failsafe off"),
    ParamSpec("INITIAL_MODE", INT8, 0, 0, 17, "mode at boot (0 STABILIZE)", allowed=(0, 4, 5, 6, 9, 17)),
    ParamSpec("FS_GCS_ENABLE", INT8, 0, 0, 7, "GCS failsafe action: " + _FAILSAFE_ACTIONS, allowed=(0, 1, 2, 5, 7)),
    ParamSpec("FS_GCS_TIMEOUT", REAL32, 5.0, 2.0, 120.0,
              "GCS failsafe after this long without a HEARTBEAT from SYSID_MYGCS (s)"),
    ParamSpec("FS_OPTIONS", INT32, 16, 0, 63,
              "failsafe options bitmask: 8 continue if landing, 16 continue in pilot-controlled modes on GCS failsafe"),
    ParamSpec("GUID_TIMEOUT", REAL32, 3.0, 0.1, 5.0,
              "GUIDED stops (zero velocity) this long after the last velocity setpoint (s)"),
    ParamSpec("RTL_ALT", INT32, 1500, 200, 300000, "RTL returns at least this high above home (cm)"),
    ParamSpec("RTL_ALT_FINAL", INT16, 0, 0, 1000, "RTL ends hovering this high above home; 0 lands (cm)"),
    ParamSpec("RTL_CLIMB_MIN", INT16, 0, 0, 3000, "RTL climbs at least this much first (cm)"),
    ParamSpec("RTL_SPEED", INT16, 0, 0, 2000, "RTL horizontal speed; 0 uses WPNAV_SPEED (cm/s)"),
    ParamSpec("RTL_LOIT_TIME", INT32, 5000, 0, 60000, "RTL hovers this long above home before descending (ms)"),
    ParamSpec("RTL_CONE_SLOPE", REAL32, 3.0, 0.0, 10.0,
              "RTL climbs less near home: return altitude <= distance x slope; < 0.5 disables"),
    ParamSpec("LAND_SPEED", INT16, 50, 30, 200, "final landing descent speed (cm/s)"),
    ParamSpec("LAND_SPEED_HIGH", INT16, 0, 0, 500,
              "landing descent speed above LAND_ALT_LOW; 0 uses WPNAV_SPEED_DN (cm/s)"),
    ParamSpec("LAND_ALT_LOW", INT16, 1000, 100, 10000, "below this altitude landing slows to LAND_SPEED (cm)"),
    ParamSpec("PILOT_SPEED_UP", INT16, 250, 50, 500, "climb speed of a takeoff in LOITER (cm/s)"),
    ParamSpec("WPNAV_SPEED", REAL32, 1000.0, 20.0, 2000.0, "horizontal speed limit in GUIDED and RTL (cm/s)"),
    ParamSpec("WPNAV_SPEED_UP", REAL32, 250.0, 10.0, 1000.0, "climb speed limit, GUIDED takeoff speed (cm/s)"),
    ParamSpec("WPNAV_SPEED_DN", REAL32, 150.0, 10.0, 500.0, "descent speed limit (cm/s)"),
    ParamSpec("AUTO_OPTIONS", INT32, 0, 0, 255,
              "AUTO mode: bit 0 allows arming in AUTO, bit 1 a takeoff without raising the throttle"),
    ParamSpec("WPNAV_RADIUS", REAL32, 200.0, 5.0, 1000.0, "AUTO: a waypoint is reached this close (cm)"),
    ParamSpec("DISARM_DELAY", INT8, 10, 0, 127, "auto-disarm this long after landing outside LAND/RTL; 0 never (s)"),
    ParamSpec("FENCE_ENABLE", INT8, 0, 0, 1, "the fences: 0 off, 1 on"),
    ParamSpec("FENCE_TYPE", INT8, 7, 0, 15,
              "fences bitmask: 1 max altitude, 2 circle around home, 4 uploaded inclusion/exclusion polygons and "
              "circles, 8 min altitude"),
    ParamSpec("FENCE_ACTION", INT8, 1, 0, 5, "breach action: 0 report only, 1 RTL or land, 2 land, 4 brake or land",
              allowed=(0, 1, 2, 4)),
    ParamSpec("FENCE_ALT_MAX", REAL32, 100.0, 10.0, 1000.0, "fence ceiling above home (m)"),
    ParamSpec("FENCE_ALT_MIN", REAL32, -10.0, -100.0, 100.0,
              "fence floor above home (m), armed once the vehicle is FENCE_MARGIN above it, off while landing"),
    ParamSpec("FENCE_RADIUS", REAL32, 300.0, 30.0, 10000.0, "circle fence radius around home (m)"),
    ParamSpec("FENCE_MARGIN", REAL32, 2.0, 1.0, 10.0, "distance the autopilot keeps from a fence (m)"),
    ParamSpec("RALLY_LIMIT_KM", REAL32, 0.3, 0.0, 1000.0,
              "RTL goes home when the closest rally point is further than this; 0: no limit (km)"),
    ParamSpec("RALLY_INCL_HOME", INT8, 1, 0, 1,
              "1: RTL goes to the closest of home and the rally points; 0: to the closest rally point"),
    # BATT_MONITOR carries AP_PARAM_FLAG_ENABLE: while it is 0 every other BATT_* parameter is hidden (not listed,
    # not readable, not settable) and there is no battery failsafe. ArduPilot's fallback default is 0; boards with
    # a power module set 4 in their hwdef (HAL_BATT_MONITOR_DEFAULT), as this simulated one does.
    ParamSpec("BATT_MONITOR", INT8, 4, 0, 30, "battery monitor: 0 none (hides the other BATT_*), 4 analog "
              "voltage and current", allowed=(0, 4)),
    ParamSpec("BATT_LOW_VOLT", REAL32, 10.5, 0.0, 100.0,
              "low-battery failsafe below this voltage for BATT_LOW_TIMER (V); 0 off", enabled_by=_MONITOR),
    ParamSpec("BATT_CRT_VOLT", REAL32, 0.0, 0.0, 100.0, "critical-battery failsafe voltage (V); 0 off",
              enabled_by=_MONITOR),
    ParamSpec("BATT_LOW_MAH", REAL32, 0.0, 0.0, 100000.0,
              "low-battery failsafe below this remaining capacity (mAh); 0 off", enabled_by=_MONITOR),
    ParamSpec("BATT_CRT_MAH", REAL32, 0.0, 0.0, 100000.0,
              "critical-battery failsafe remaining capacity (mAh); 0 off", enabled_by=_MONITOR),
    ParamSpec("BATT_LOW_TIMER", INT8, 10, 0, 120, "the voltage must stay below a threshold this long (s)",
              enabled_by=_MONITOR),
    ParamSpec("BATT_FS_LOW_ACT", INT8, 0, 0, 7, "low-battery action: " + _BATTERY_ACTIONS, allowed=(0, 1, 2, 7),
              enabled_by=_MONITOR),
    ParamSpec("BATT_FS_CRT_ACT", INT8, 0, 0, 7, "critical-battery action: " + _BATTERY_ACTIONS,
              allowed=(0, 1, 2, 7), enabled_by=_MONITOR),
    ParamSpec("BATT_ARM_VOLT", REAL32, 0.0, 0.0, 100.0, "arming refused below this voltage (V); 0 off",
              enabled_by=_MONITOR),
) + tuple(
    ParamSpec(f"SR{link}_{group}", INT16, 0, 0, 50,
              f"stream rate of the {group} group on link {link} (Hz); REQUEST_DATA_STREAM changes it at once, "
              "PARAM_SET at the next boot")
    for link in range(STREAM_LINKS) for group in STREAM_GROUPS)

