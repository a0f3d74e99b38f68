"""What differs between the autopilots the runner flies: PX4 and ArduPilot Copter.

The runner's state machine is the same for both; an :class:`AutopilotFlavour` says, for the autopilot named in the
vehicle's HEARTBEAT (``autopilot`` field), which mode the companion computer flies in, how modes are requested, how
the take-off command is written and what the autopilot's own link-loss failsafes look like. What each value is was
checked against the autopilots' sources and documentation (docs/runner.md, "Autopilots", cites them):

* **PX4** (MAV_AUTOPILOT_PX4): the companion flies in OFFBOARD (custom main mode 6), entered with MAV_CMD_DO_SET_MODE
  (param1 CUSTOM_MODE_ENABLED, param2 main mode, param3 sub mode) while setpoints are streaming. Take-off is the
  AUTO.TAKEOFF mode, started by MAV_CMD_NAV_TAKEOFF whose param7 is an altitude above mean sea level; it ends in
  HOLD (AUTO.LOITER). Arming works in HOLD. Offboard loss (no setpoint for COM_OF_LOSS_T) switches to the
  COM_OBL_RC_ACT mode: POSCTL, HOLD, RTL or LAND.
* **ArduPilot Copter** (MAV_AUTOPILOT_ARDUPILOTMEGA): the companion flies in GUIDED (custom mode 4), where velocity
  setpoints are obeyed without a proof-of-life rule; a velocity setpoint older than GUID_TIMEOUT (3 s) makes the
  vehicle stop, in GUIDED. Take-off is MAV_CMD_NAV_TAKEOFF in GUIDED, armed, param7 the height above home in metres
  (ArduCopter GCS_Mavlink.cpp, ``handle_command_long_packet``); the vehicle stays in GUIDED. Modes are requested
  with MAV_CMD_DO_SET_MODE, param2 the mode number. The GCS failsafe (FS_GCS_ENABLE) switches to RTL, LAND,
  SMART_RTL or BRAKE; it announces itself with a "GCS Failsafe" STATUSTEXT.

Mode names are pymavlink's (``mavutil.mode_string_v10``): "OFFBOARD", "LOITER" (PX4's HOLD), "RTL", ... for PX4;
"GUIDED", "LOITER", "RTL", "BRAKE", ... for ArduPilot Copter.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

CUSTOM = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
PX4_MODES = {"OFFBOARD": (6, 0), "LOITER": (4, 3), "RTL": (4, 5), "LAND": (4, 6), "POSCTL": (3, 0)}
"""PX4 (main, sub) custom modes the runner requests, by pymavlink's names (px4_custom_mode.h)."""
ARDUPILOT_COPTER_MODES = {name: number for number, name in mavutil.mode_mapping_acm.items()}


class UnsupportedAutopilot(ValueError):
    """The vehicle's autopilot is neither PX4 nor ArduPilot: the runner does not know its modes."""


@dataclass(frozen=True)
class AutopilotFlavour:
    """How one autopilot is flown by the runner (see the module docstring)."""

    name: str
    """For logs and reports: "PX4" or "ArduPilot Copter"."""
    companion_mode: str
    """The mode in which the vehicle follows the companion's velocity setpoints."""
    takeoff_mode: str | None
    """The mode the vehicle climbs in after MAV_CMD_NAV_TAKEOFF (None: it climbs in ``arm_mode``)."""
    arm_mode: str | None
    """The mode to request before arming (None: arm in whatever mode the vehicle is in)."""
    failsafe_modes: frozenset[str]
    """Modes the autopilot's own link-loss failsafes switch to."""
    failsafe_text: re.Pattern | None
    """STATUSTEXTs (lower case) that announce such a (link-loss) failsafe (None: the autopilot names no cause)."""
    safety_text: re.Pattern
    """STATUSTEXTs (lower case) that announce one of the autopilot's other failsafes (geofence, battery, estimator):
    a mode change they explain is the autopilot keeping the drone safe, and the search must not resume over it."""
    takeoff_altitude_amsl: bool
    """Whether MAV_CMD_NAV_TAKEOFF's param7 is an AMSL altitude (PX4) rather than a height above home."""
    setpoint_timeout_s: float | None
    """After this long without a setpoint the vehicle stops on its own and stays in the companion mode (ArduPilot's
    GUID_TIMEOUT default); None: it leaves the mode instead (PX4's offboard loss)."""

    def mode_params(self, mode: str) -> tuple[float, ...]:
        """MAV_CMD_DO_SET_MODE param1..3 requesting ``mode``."""
        if self.name == "PX4":
            main, sub = PX4_MODES[mode]
            return float(CUSTOM), float(main), float(sub)
        return float(CUSTOM), float(ARDUPILOT_COPTER_MODES[mode]), 0.0

    def takeoff_params(self, home_amsl_m: float, height_m: float) -> tuple[float, ...]:
        """MAV_CMD_NAV_TAKEOFF param1..7 climbing to ``height_m`` above the vehicle's home."""
        if self.takeoff_altitude_amsl:  # PX4: NaN leaves pitch, yaw and position to the autopilot
            return math.nan, 0.0, 0.0, math.nan, math.nan, math.nan, home_amsl_m + height_m
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, height_m


PX4 = AutopilotFlavour(
    name="PX4", companion_mode="OFFBOARD", takeoff_mode="TAKEOFF", arm_mode=None,
    failsafe_modes=frozenset({"POSCTL", "LOITER", "RTL", "LAND"}),
    # PX4 >= 1.14 says "Failsafe activated" whatever the cause (FailsafeBase::notifyUser; the cause goes out as an
    # event), so no STATUSTEXT announces the offboard-loss failsafe: silences and deaf stretches are the evidence.
    # Its health checks' texts do name the geofence ("Geofence: exceeding maximum distance to Home") and the
    # battery ("Critical battery", "Emergency battery level"): docs/runner.md. "Failsafe activated, entering Hold
    # for N seconds" comes only before a Return or Land whose takeover setting is "auto" (COM_FAIL_ACT_T; the
    # geofence's, the battery's), never before the offboard-loss fallback: resuming in that Hold would cancel it.
    failsafe_text=None,
    safety_text=re.compile(r"geofence|battery|entering hold for|estimator|navigation failure"),
    takeoff_altitude_amsl=True, setpoint_timeout_s=None)

ARDUPILOT_COPTER = AutopilotFlavour(
    name="ArduPilot Copter", companion_mode="GUIDED", takeoff_mode=None, arm_mode="GUIDED",
    failsafe_modes=frozenset({"RTL", "LAND", "SMART_RTL", "BRAKE", "LOITER"}),
    failsafe_text=re.compile(r"gcs failsafe(?! cleared)"),
    safety_text=re.compile(r"fences? breached|battery|ekf"),
    takeoff_altitude_amsl=False, setpoint_timeout_s=3.0)


def flavour_for(autopilot: int) -> AutopilotFlavour:
    """The flavour for a HEARTBEAT's ``autopilot`` field; raises UnsupportedAutopilot for any other autopilot."""
    if autopilot == mavlink.MAV_AUTOPILOT_PX4:
        return PX4
    if autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA:
        return ARDUPILOT_COPTER
    entry = mavlink.enums["MAV_AUTOPILOT"].get(autopilot)
    raise UnsupportedAutopilot(f"the vehicle's autopilot is {entry.name if entry else autopilot}: the runner flies "
                               "PX4 (MAV_AUTOPILOT_PX4) and ArduPilot Copter (MAV_AUTOPILOT_ARDUPILOTMEGA) only")


LINK_LOSS_PARAM = {"PX4": "COM_OBL_RC_ACT", "ArduPilot Copter": "FS_GCS_ENABLE"}
"""The parameter that sets what the autopilot's link-loss failsafe switches to."""
LINK_LOSS_MODES = {
    # PX4 COM_OBL_RC_ACT (failsafe.cpp fromOfflossActParam): 0 Position, which without RC cannot run and falls
    # through Altitude and Stabilized to Hold (getSelectedAction); 3 Return, 4 Land, 5 Hold.
    "PX4": {0: {"POSCTL", "LOITER"}, 3: {"RTL"}, 4: {"LAND"}, 5: {"LOITER"}},
    # ArduCopter FS_GCS_ENABLE (Parameters.cpp @Values): 0 no action (GUIDED only stops after GUID_TIMEOUT), 1 RTL,
    # 2 RTL (AUTO continues), 3 SmartRTL or RTL, 4 SmartRTL or Land, 5 Land, 6 Auto DO_LAND_START or RTL, 7 Brake or
    # Land. LAND is kept for each: the fallback when the first choice cannot run.
    "ArduPilot Copter": {0: set(), 1: {"RTL", "LAND"}, 2: {"RTL", "LAND"}, 3: {"SMART_RTL", "RTL", "LAND"},
                         4: {"SMART_RTL", "LAND"}, 5: {"LAND"}, 6: {"RTL", "LAND"}, 7: {"BRAKE", "LAND"}},
}


def link_loss_modes(flavour: AutopilotFlavour, params: dict[str, float]) -> frozenset[str]:
    """The modes this vehicle's own link-loss failsafe may switch to, from its parameters as read (all of the
    flavour's failsafe modes while the parameter is unread or its value unknown)."""
    value = params.get(LINK_LOSS_PARAM[flavour.name])
    modes = LINK_LOSS_MODES[flavour.name].get(int(value)) if value is not None and math.isfinite(value) else None
    return flavour.failsafe_modes if modes is None else flavour.failsafe_modes & frozenset(modes)
