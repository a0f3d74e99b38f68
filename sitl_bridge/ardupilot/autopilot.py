"""ArduPilot Copter behaviour of the simulated vehicle: modes, arming, takeoff, GUIDED setpoints, RTL, LAND.

The same dynamics, sensors, telemetry and links as the PX4 personality; only the rules differ. Each rule follows
ArduPilot's source, read through the search tools (docs/sitl.md, "ArduPilot Copter", names files and functions):

* Boot in INITIAL_MODE (STABILIZE). Disarmed, any emulated mode may be entered; armed, GUIDED/LOITER/RTL/BRAKE need
  a position. DO_SET_MODE and SET_MODE answer ACCEPTED or FAILED (SET_MODE too gets a COMMAND_ACK, command 11).
* Arming from a ground station in STABILIZE, GUIDED or LOITER only; pre-arm failures say "PreArm: ..."; results
  are FAILED; param2 2989 forces an arm, 21196 a disarm; disarming in the air is FAILED. Landed, ArduPilot reports
  MAV_STATE_STANDBY even when armed. Home is re-set where the vehicle arms.
* MAV_CMD_NAV_TAKEOFF: param7 in metres above home, armed and landed, in GUIDED or LOITER; the vehicle stays in
  its mode when the climb completes.
* GUIDED: velocity and position targets (SET_POSITION_TARGET_LOCAL_NED); GUID_TIMEOUT (3 s) after the last
  velocity the target becomes zero and the vehicle stays in GUIDED; invalid targets stop it. MAV_CMD_DO_REPOSITION
  (COMMAND_INT only; MAVSDK's goto_location) sets a GUIDED position target, switching to GUIDED with its flag.
* RTL climbs (RTL_ALT, cone slope), returns, hovers RTL_LOIT_TIME, lands; LAND and RTL disarm once landed, other
  modes DISARM_DELAY after landing; RTL goes to the closest rally point when AP_Rally says so
  (:mod:`sitl_bridge.ardupilot.rally`). AUTO flies the uploaded mission (:mod:`sitl_bridge.ardupilot.auto`; the
  protocol: :mod:`sitl_bridge.ardupilot.mission_protocol`). Failsafes: :mod:`sitl_bridge.ardupilot.failsafes`;
  fences: :mod:`sitl_bridge.ardupilot.fence`; the modes' velocity commands: :mod:`sitl_bridge.ardupilot.guidance`.

``autopilot.mode`` is a :class:`CopterMode`; ``autopilot.status`` is the personality-neutral view
(:class:`sitl_bridge.autopilot_base.FlightStatus`).
"""
from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from missions.geodesy import LocalFrame
from sitl_bridge.ardupilot.auto import CopterAuto
from sitl_bridge.ardupilot.failsafes import CopterFailsafes
from sitl_bridge.ardupilot.fence import CopterFence
from sitl_bridge.ardupilot.guidance import CopterGuidance
from sitl_bridge.ardupilot.modes import OTHER_COPTER_MODES, CopterMode, base_mode
from sitl_bridge.ardupilot.rally import CopterRally
from sitl_bridge.ardupilot.targets import GuidedTargets
from sitl_bridge.autopilot_base import (
    ABOVE_HOME_FRAMES,
    ACCEPTED,
    DENIED,
    FAILED,
    UNSUPPORTED,
    AutopilotBase,
    FlightStatus,
    Setpoint,
    as_int,
    battery_voltage_v,
)
from sitl_bridge.dynamics import velocity_toward
from sitl_bridge.multirotor import HOVER, MultirotorParams, VehicleState, VelocityCommand
from sitl_bridge.params import ParameterStore

FORCE_ARM_MAGIC = 2989  # GCS_MAVLINK::magic_force_arm_value
FORCE_DISARM_MAGIC = 21196  # GCS_MAVLINK::magic_force_disarm_value
LAND_DETECTOR_TRIGGER_S = 1.0  # land_detector.cpp: LAND_DETECTOR_TRIGGER_SEC
LAND_WITH_PAUSE_S = 4.0  # a failsafe LAND waits this long before descending (set_mode_land_with_pause)
RTL_ALT_MIN_M = 2.0
RTL_MIN_CONE_SLOPE = 0.5
FLIGHT_SW_VERSION = (4 << 24) | (5 << 16) | (7 << 8) | 255  # reported as ArduCopter V4.5.7, official release
# What we implement of what ArduCopter claims (it also claims FTP, attitude targets...).
# No PARAM_ENCODE_BYTEWISE: ArduPilot parameters are floats. MISSION_INT: MAVSDK transfers missions only with it.
CAPABILITIES = (mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
                | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
                | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2)
STOP = VelocityCommand()  # zero velocity, heading held
PHASE_OF_MODE = {CopterMode.GUIDED: "guided", CopterMode.LOITER: "holding", CopterMode.BRAKE: "holding",
                 CopterMode.RTL: "returning", CopterMode.LAND: "landing", CopterMode.STABILIZE: "manual",
                 CopterMode.AUTO: "mission"}


class ArduCopter(CopterAuto, CopterFailsafes, CopterFence, CopterRally, CopterGuidance, GuidedTargets, AutopilotBase):
    """Modes, arming and command handling of one simulated ArduCopter."""

    PARAMS_BYTEWISE = False
    MAV_AUTOPILOT = mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
    CAPABILITIES = CAPABILITIES
    FLIGHT_SW_VERSION = FLIGHT_SW_VERSION

    def __init__(self, params: ParameterStore, airframe: MultirotorParams, frame: LocalFrame):
        super().__init__(params, airframe, frame)
        self.mode = CopterMode(int(params["INITIAL_MODE"]))
        self.land_complete = True
        self._ground_since_s = -math.inf
        self._landed_armed_since_s: float | None = None  # for DISARM_DELAY
        self.hold_target: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.taking_off = False
        self.rtl_state = "climb"
        self.rtl_return_down_m = 0.0
        self.rtl_target: tuple[float, float] = (0.0, 0.0)  # where RTL returns to: home or a rally point (north, east)
        self._rtl_loiter_since_s: float | None = None
        self.land_pause_until_s = -math.inf
        self.guided_timed_out = False
        self.guided_timeouts = 0
        self.gcs_last_seen_s: float | None = None
        self.gcs_failsafe = False
        self.battery_failsafe = 0  # 0 none, 1 low, 2 critical
        self._battery_low_since_s: dict[int, float] = {}
        self.home_changed = True  # AP_AHRS::set_home at the first position fix sends HOME_POSITION on every link
        self.auto_reached_news = []

    # ----------------------------------------------------------------- what the vehicle reports
    @property
    def motors_running(self) -> bool:
        # STABILIZE with no pilot (throttle stick low) gives no thrust: in the air the vehicle falls.
        return self.armed and not (self.mode is CopterMode.STABILIZE and not self.land_complete)

    def heartbeat_fields(self) -> tuple[int, int, int, int]:
        if self.gcs_failsafe or self.battery_failsafe:
            status = mavlink.MAV_STATE_CRITICAL
        elif self.land_complete:
            status = mavlink.MAV_STATE_STANDBY
        else:
            status = mavlink.MAV_STATE_ACTIVE
        return self.MAV_AUTOPILOT, base_mode(self.mode, self.armed, not self.land_complete), int(self.mode), status

    @property
    def battery_monitored(self) -> bool:
        return self.params["BATT_MONITOR"] != 0

    @property
    def battery_healthy(self) -> bool:
        # GCS_Common.cpp update_sensor_status_flags: healthy only while battery.healthy() && !has_failsafed()
        return self.battery_monitored and self.battery_failsafe == 0

    def battery_charge_state(self, fraction: float) -> int:
        return (mavlink.MAV_BATTERY_CHARGE_STATE_OK, mavlink.MAV_BATTERY_CHARGE_STATE_LOW,
                mavlink.MAV_BATTERY_CHARGE_STATE_CRITICAL)[self.battery_failsafe]

    @property
    def is_landing(self) -> bool:
        """Mode::is_landing: LAND, RTL in its final descent, or AUTO landing (a LAND command, or its RTL's)."""
        rtl_landing = self.rtl_state == "land" and (self.mode is CopterMode.RTL or self.auto_submode == "rtl")
        auto_landing = self.mode is CopterMode.AUTO and (self.auto_submode == "land" and self._land_descending
                                                        or self.auto_submode == "rtl" and rtl_landing)
        return self.mode is CopterMode.LAND or (self.mode is CopterMode.RTL and rtl_landing) or auto_landing

    def landed_state(self, state: VehicleState) -> int:
        """GCS_MAVLINK_Copter::landed_state(): from the land detector, not the instant of touchdown."""
        if self.land_complete:
            return mavlink.MAV_LANDED_STATE_ON_GROUND
        if self.is_landing:
            return mavlink.MAV_LANDED_STATE_LANDING
        if self.taking_off:
            return mavlink.MAV_LANDED_STATE_TAKEOFF
        return mavlink.MAV_LANDED_STATE_IN_AIR

    def prearm_failure(self, state: VehicleState) -> str | None:
        """The pre-arm check that fails (its text after "PreArm: "), or None."""
        if self.mode.requires_gps and not self.gps_ok:
            return "Need Position Estimate"
        if self.gcs_failsafe:
            return "GCS failsafe on"
        fence = self.fence_prearm_failure()
        if fence:
            return fence
        arm_volt = self.params["BATT_ARM_VOLT"] if self.battery_monitored else 0.0
        if arm_volt > 0 and battery_voltage_v(self.battery_fraction(state)) < arm_volt:
            return "Battery 1 below minimum arming voltage"
        return None

    @property
    def status(self) -> FlightStatus:
        phase = PHASE_OF_MODE[self.mode]
        if self.taking_off:
            phase = "taking_off"
        elif self.mode is CopterMode.RTL and self.rtl_state == "land":
            phase = "landing"
        if not self.armed or (self.land_complete and not self.taking_off):
            phase = "on_ground"
        return FlightStatus(self.armed, self.mode.name, phase, self.setpoint.time_s if self.setpoint else None,
                            self.params["GUID_TIMEOUT"])

    # ----------------------------------------------------------------- modes and arming
    def set_mode(self, number: int, now: float, state: VehicleState, reason: str) -> bool:
        """Copter::set_mode: True when the vehicle is (now) in mode ``number``."""
        try:
            mode = CopterMode(number)
        except ValueError:
            if number in OTHER_COPTER_MODES:  # exists in ArduCopter, not emulated here (real ArduPilot switches)
                self._event(now, f"Mode change to {OTHER_COPTER_MODES[number]} failed: not emulated",
                            mavlink.MAV_SEVERITY_WARNING)
            else:
                self._event(now, f"No such mode {number}", mavlink.MAV_SEVERITY_WARNING)
            return False
        if mode is self.mode:
            return True
        if self.armed and mode.requires_gps and not self.gps_ok:  # ignore_checks = !armed
            self._event(now, f"Mode change to {mode.name} failed: requires position", mavlink.MAV_SEVERITY_WARNING)
            return False
        if mode is CopterMode.AUTO and not self._auto_init(now, state):
            self._event(now, "Mode change to AUTO failed: init failed", mavlink.MAV_SEVERITY_WARNING)
            return False
        if self.mode is CopterMode.AUTO:
            self._auto_left()
        self.mode, self.state_changed, self.taking_off = mode, True, False  # exit_mode stops a takeoff
        here = (state.north_m, state.east_m, 0.0 if state.on_ground else state.down_m)
        if mode in (CopterMode.GUIDED, CopterMode.LOITER):
            self.hold_target, self.setpoint, self.guided_timed_out = here, None, False
        elif mode is CopterMode.LAND:
            self.hold_target = here
            self.land_pause_until_s = now + LAND_WITH_PAUSE_S if "failsafe" in reason else -math.inf
        elif mode is CopterMode.RTL:
            self._rtl_start(state)
        self._fence_recovery_start(now)
        self._event(now, f"mode {mode.name} ({reason})", broadcast=False)
        if mode is CopterMode.AUTO:
            self._auto_entered(now, state)
        return True

    def _rtl_start(self, state: VehicleState) -> None:
        """ModeRTL::compute_return_target: where to return (home or a rally point) and the altitude above home to
        return at."""
        home_d = self.home_ned[2]
        target_n, target_e, target_alt = self.rtl_return_target(state)
        self.rtl_target = (target_n, target_e)
        alt = home_d - state.down_m
        min_alt = max(RTL_ALT_MIN_M, alt + max(0.0, self.params["RTL_CLIMB_MIN"] / 100.0))
        target = max(max(target_alt, 0.0), max(self.params["RTL_ALT"] / 100.0, min_alt))
        if self.params["RTL_CONE_SLOPE"] >= RTL_MIN_CONE_SLOPE:
            distance = math.hypot(state.north_m - target_n, state.east_m - target_e)
            target = min(target, max(distance * self.params["RTL_CONE_SLOPE"], min_alt))
        self.rtl_return_down_m = home_d - max(target, alt)
        self.rtl_state, self._rtl_loiter_since_s = "climb", None

    def arm(self, now: float, state: VehicleState, force: bool) -> int:
        if self.armed:
            return ACCEPTED
        if not force:  # AP_Arming::arm: pre_arm_checks ("PreArm: ...") then arm_checks ("Arm: ...")
            failure = self.prearm_failure(state)
            if failure:
                self._event(now, f"PreArm: {failure}", mavlink.MAV_SEVERITY_CRITICAL)
                return FAILED
            auto_armable = self.mode is CopterMode.AUTO and int(self.params["AUTO_OPTIONS"]) & 1  # AllowArming
            if not (self.mode.allows_arming or auto_armable):  # 4.5's text; master names the mode
                self._event(now, "Arm: Mode not armable", mavlink.MAV_SEVERITY_CRITICAL)
                return FAILED
        self.armed, self.state_changed, self._landed_armed_since_s = True, True, now
        self.battery_failsafe, self._battery_low_since_s = 0, {}
        if state.on_ground:  # AP_Arming_Copter::arm: home is set where the vehicle arms (AP_AHRS::set_home sends it)
            self.home_ned, self.home_changed = (state.north_m, state.east_m, 0.0), True
        self._event(now, "Arming motors")
        if self.mode is CopterMode.AUTO and self.mission_state != "running":
            self._auto_entered(now, state)
        return ACCEPTED

    def disarm(self, now: float, force: bool, reason: str) -> int:
        """MAVLink disarm: refused (FAILED) unless landed or forced."""
        if not self.armed:
            return ACCEPTED
        if not force and not self.land_complete:
            return FAILED
        self._disarm(now, reason)
        return ACCEPTED

    def _disarm(self, now: float, reason: str) -> None:
        self.armed, self.state_changed, self.taking_off = False, True, False
        self._auto_disarmed()
        self._event(now, "Disarming motors")
        self._event(now, f"disarmed ({reason})", broadcast=False)

    # ----------------------------------------------------------------- commands
    def handle_command(self, command: int, p: tuple[float, ...], now: float, state: VehicleState,
                       source_component: int = 190, frame: int | None = None) -> int:
        """One MAV_CMD with params p[0..6]; returns the MAV_RESULT ArduCopter gives (repeats have no second effect)."""
        if command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            if p[0] == 1:
                return self.arm(now, state, force=p[1] == FORCE_ARM_MAGIC)
            if p[0] == 0:
                return self.disarm(now, force=p[1] == FORCE_DISARM_MAGIC, reason="command")
            return UNSUPPORTED
        if command == mavlink.MAV_CMD_NAV_TAKEOFF:
            if frame is not None and frame != mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT:
                return DENIED
            return ACCEPTED if self._user_takeoff(p[6], now, state) else FAILED
        modes = {mavlink.MAV_CMD_NAV_LAND: CopterMode.LAND, mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH: CopterMode.RTL,
                 mavlink.MAV_CMD_NAV_LOITER_UNLIM: CopterMode.LOITER}
        if command in modes:
            return ACCEPTED if self.set_mode(modes[command], now, state, "command") else FAILED
        if command == mavlink.MAV_CMD_DO_SET_MODE:
            if not as_int(p[0], 0) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
                return DENIED  # GCS_MAVLINK::_set_mode_common: only custom modes
            return ACCEPTED if self.set_mode(as_int(p[1], 0) & 0xFF, now, state, "DO_SET_MODE") else FAILED
        if command == mavlink.MAV_CMD_SET_CAMERA_ZOOM:
            return self._zoom(as_int(p[0]), p[1], now)
        if command == mavlink.MAV_CMD_MISSION_START:
            return self._mission_start(p, now, state)
        if command == mavlink.MAV_CMD_DO_REPOSITION and frame is not None:
            return self._reposition(p, frame, now, state)
        return UNSUPPORTED

    def _reposition(self, p: tuple[float, ...], frame: int, now: float, state: VehicleState) -> int:
        """GCS_MAVLINK_Copter::handle_command_int_do_reposition (a COMMAND_INT; x/y degrees * 1e7, z metres in the
        command's frame): outside GUIDED it needs param2's MAV_DO_REPOSITION_FLAGS_CHANGE_MODE (else DENIED); a
        latitude/longitude out of range or both zero, or 0 m above home (Location::sanitize reads those as "here"
        and "this altitude", and a location it had to change is refused), or a frame other than global (AMSL)
        or relative to home (ArduPilot also takes terrain frames; no terrain is simulated), DENIED; then GUIDED
        flies to the point at WPNAV_SPEED and holds (no yaw change); FAILED if GUIDED cannot be entered. Armed on
        the ground the point is not taken (not checked against ArduPilot: a GUIDED takeoff replaces it there
        anyway)."""
        change_mode = as_int(p[1], 0) & 1
        if self.mode is not CopterMode.GUIDED and not change_mode:
            return DENIED
        x, y, z = p[4], p[5], p[6]
        # location_from_command_t stores the altitude in whole centimetres (truncated): below 1 cm it is 0
        zero_above_home = frame in ABOVE_HOME_FRAMES and math.isfinite(z) and int(z * 100.0) == 0
        target = self.global_target(frame, x, y, z) if abs(x) <= 90e7 and abs(y) <= 180e7 and (x, y) != (0, 0) \
            and not zero_above_home else "no place"
        if isinstance(target, str):
            return DENIED
        if not self.set_mode(CopterMode.GUIDED, now, state, "DO_REPOSITION"):
            return FAILED
        if self.armed and not state.on_ground:
            self.setpoint = Setpoint(now, False, *target)
        return ACCEPTED

    def handle_set_mode_message(self, base_mode: int, custom_mode: int, now: float, state: VehicleState) -> int | None:
        """SET_MODE: handled like DO_SET_MODE, and ArduPilot ACKs it (COMMAND_ACK with command 11)."""
        if not base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return DENIED
        return ACCEPTED if self.set_mode(custom_mode & 0xFF, now, state, "SET_MODE") else FAILED

    def _user_takeoff(self, alt_above_home_m: float, now: float, state: VehicleState) -> bool:
        """Mode::do_user_takeoff: armed, landed, a mode with user takeoff, and upwards."""
        home_n, home_e, home_d = self.home_ned
        if not (self.armed and self.land_complete and self.mode.has_user_takeoff and math.isfinite(alt_above_home_m)):
            return False
        if alt_above_home_m <= home_d - state.down_m:  # can't take off downwards
            return False
        self.hold_target = (state.north_m, state.east_m, home_d - alt_above_home_m)
        self.taking_off, self.setpoint = True, None
        self._event(now, f"takeoff to {alt_above_home_m:.1f} m above home", broadcast=False)
        return True

    # ----------------------------------------------------------------- the control loop
    def guidance(self, now: float, state: VehicleState) -> VelocityCommand:
        """Land detector, failsafes and auto-disarm, then this tick's velocity command for the dynamics."""
        self._update_land_detector(now, state)
        self._check_fence(now, state, self.is_landing or self.land_complete or not self.armed)
        self._check_gcs_failsafe(now, state)
        if self.armed and not state.on_ground:
            self._check_battery(now, state)
        if not self.armed:
            return HOVER
        if self.mode is CopterMode.AUTO:
            command = self._auto_command(now, state)
            if self.armed:
                self._auto_disarm(now)  # DISARM_DELAY while the takeoff waits on the ground
            return command if self.armed else HOVER
        self._auto_disarm(now)
        if not self.armed or self.mode is CopterMode.STABILIZE:
            return HOVER
        if self.taking_off:
            return self._takeoff_command(state)
        if self.land_complete:  # is_disarmed_or_landed(): modes do nothing on the ground
            return HOVER
        speed_xy = self.params["WPNAV_SPEED"] / 100.0
        if self.mode is CopterMode.GUIDED:
            return self._guided_command(now, state, speed_xy)
        if self.mode is CopterMode.LOITER:
            return velocity_toward(state, *self.hold_target, self.airframe, speed_xy_mps=speed_xy)
        if self.mode is CopterMode.BRAKE:
            return STOP
        if self.mode is CopterMode.LAND:
            return self._landing_command(now, state, self.hold_target[0], self.hold_target[1])
        return self._rtl_command(now, state)

    def _update_land_detector(self, now: float, state: VehicleState) -> None:
        if not state.on_ground:
            self.land_complete, self._ground_since_s = False, math.inf
        elif not self.land_complete:
            self._ground_since_s = min(self._ground_since_s, now)
            if now - self._ground_since_s >= LAND_DETECTOR_TRIGGER_S and not self.taking_off:
                self.land_complete = True

    def _auto_disarm(self, now: float) -> None:
        """LAND and RTL's landing disarm when landed; other modes DISARM_DELAY after landing (auto_disarm_check)."""
        if not self.land_complete or self.taking_off:
            self._landed_armed_since_s = None
            return
        if self.is_landing:
            self._disarm(now, "landed")
            return
        if self._landed_armed_since_s is None:
            self._landed_armed_since_s = now
        delay = self.params["DISARM_DELAY"]
        if delay > 0 and now - self._landed_armed_since_s > delay:
            self._disarm(now, "auto-disarm after DISARM_DELAY")
