"""PX4-flavoured autopilot logic: arming, modes, commands, offboard rules and failsafes.

No I/O and no MAVLink encoding here: the vehicle hands decoded commands and setpoints in, and asks
:meth:`Autopilot.guidance` for the velocity command the dynamics should fly this tick. What PX4 does and
why we copy it is noted where it matters; ``docs/sitl.md`` lists the differences.
"""
from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.dynamics import HOVER, MultirotorParams, VehicleState, VelocityCommand, velocity_toward
from sitl_bridge.params import ParameterStore
from sitl_bridge.px4_modes import FlightMode

ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
TEMPORARILY_REJECTED = mavlink.MAV_RESULT_TEMPORARILY_REJECTED
DENIED = mavlink.MAV_RESULT_DENIED
UNSUPPORTED = mavlink.MAV_RESULT_UNSUPPORTED
FAILED = mavlink.MAV_RESULT_FAILED

FORCE_MAGIC = 21196  # MAV_CMD_COMPONENT_ARM_DISARM param2: arm/disarm without checks
# Offboard proof of life: PX4 wants setpoints at > 2 Hz (no gap over 0.5 s) for 1 s before the switch.
STREAM_MAX_GAP_S = 0.5
STREAM_MIN_DURATION_S = 1.0
ARRIVED_RADIUS_M = 0.3

# SET_POSITION_TARGET_LOCAL_NED.type_mask bits (POSITION_TARGET_TYPEMASK)
MASK_POSITION = 0b111
MASK_VELOCITY = 0b111000
MASK_ACCELERATION = 0b111000000
MASK_YAW = 1024
MASK_YAW_RATE = 2048

def as_int(value: float, default: int = -1) -> int:
    """A command parameter as an integer; NaN/inf (MAVSDK sends NaN for unused params) become ``default``."""
    return int(value) if math.isfinite(value) else default


FAILSAFE_MODES = {0: FlightMode.POSCTL, 3: FlightMode.RTL, 4: FlightMode.LAND, 5: FlightMode.HOLD}


@dataclass(frozen=True)
class Setpoint:
    """An accepted offboard setpoint, already in local NED."""

    time_s: float
    is_velocity: bool  # else a position
    north: float
    east: float
    down: float
    yaw_rad: float | None = None
    yaw_rate_rad_s: float | None = None


@dataclass(frozen=True)
class AutopilotEvent:
    """Something worth telling the operator (STATUSTEXT) and the log."""

    time_s: float
    text: str
    severity: int = mavlink.MAV_SEVERITY_INFO


class Autopilot:
    """Modes, arming and command handling of one simulated PX4 multirotor."""

    def __init__(self, params: ParameterStore, airframe: MultirotorParams, home_alt_m: float):
        self.params = params
        self.airframe = airframe
        self.home_alt_m = home_alt_m  # AMSL; NAV_TAKEOFF's param7 is an AMSL altitude in PX4
        self.armed = False
        self.mode = FlightMode.HOLD
        self.gps_ok = False  # set by the vehicle from the sensors; required to arm
        self.events: list[AutopilotEvent] = []
        self.state_changed = False  # a mode or arming change the vehicle must announce at once
        self.hold_target: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.takeoff_alt_m = 0.0
        self.rtl_landing = False
        self.armed_at_s = 0.0
        self.has_flown = False
        self.ground_since_s: float | None = None
        self.battery_failsafe = ""
        self.zoom_percent = 0.0
        # offboard stream bookkeeping
        self.setpoint: Setpoint | None = None
        self.stream_start_s: float | None = None
        self.setpoints_accepted = 0
        self.setpoints_ignored: Counter[str] = Counter()

    # ----------------------------------------------------------------- bookkeeping helpers
    def _event(self, now: float, text: str, severity: int = mavlink.MAV_SEVERITY_INFO) -> None:
        self.events.append(AutopilotEvent(now, text, severity))

    def stream_ok(self, now: float) -> bool:
        """Have offboard setpoints arrived at > 2 Hz for at least 1 s, up to now?"""
        return (self.setpoint is not None and self.stream_start_s is not None
                and now - self.setpoint.time_s <= STREAM_MAX_GAP_S
                and now - self.stream_start_s >= STREAM_MIN_DURATION_S)

    def landed_state(self, state: VehicleState) -> int:
        """MAV_LANDED_STATE for EXTENDED_SYS_STATE."""
        if state.on_ground:
            return mavlink.MAV_LANDED_STATE_ON_GROUND
        if self.mode is FlightMode.TAKEOFF:
            return mavlink.MAV_LANDED_STATE_TAKEOFF
        if self.mode is FlightMode.LAND or (self.mode is FlightMode.RTL and self.rtl_landing):
            return mavlink.MAV_LANDED_STATE_LANDING
        return mavlink.MAV_LANDED_STATE_IN_AIR

    def prearm_failure(self, state: VehicleState) -> str | None:
        """Why arming is refused, or None when the pre-arm checks pass."""
        if not self.gps_ok:
            return "no GPS fix"
        if state.battery_wh / self.airframe.battery_capacity_wh <= self.params["BAT_CRIT_THR"]:
            return "battery below BAT_CRIT_THR"
        return None

    # ----------------------------------------------------------------- modes and arming
    def set_mode(self, mode: FlightMode, now: float, state: VehicleState, reason: str) -> int:
        """Switch mode as PX4's commander would; returns a MAV_RESULT."""
        if mode is FlightMode.OFFBOARD and self.mode is not FlightMode.OFFBOARD and not self.stream_ok(now):
            self._event(now, "Switching to Offboard is not possible: no setpoint stream", mavlink.MAV_SEVERITY_WARNING)
            return TEMPORARILY_REJECTED
        if mode is self.mode:
            return ACCEPTED
        self.mode = mode
        self.state_changed = True
        if mode in (FlightMode.HOLD, FlightMode.POSCTL):
            self.hold_target = (state.north_m, state.east_m, 0.0 if state.on_ground else state.down_m)
        elif mode is FlightMode.TAKEOFF:
            self.hold_target = (state.north_m, state.east_m, -self.takeoff_alt_m)
        elif mode is FlightMode.LAND:
            self.hold_target = (state.north_m, state.east_m, 0.0)
        elif mode is FlightMode.RTL:
            self.rtl_landing = False
        self._event(now, f"mode {mode.name} ({reason})")
        return ACCEPTED

    def arm(self, now: float, state: VehicleState, force: bool) -> int:
        if self.armed:
            return ACCEPTED
        failure = None if force else self.prearm_failure(state)
        if failure:
            self._event(now, f"Arming denied: {failure}", mavlink.MAV_SEVERITY_CRITICAL)
            return TEMPORARILY_REJECTED
        self.armed, self.state_changed = True, True
        self.armed_at_s, self.has_flown, self.ground_since_s = now, False, None
        self.battery_failsafe = ""
        if self.mode in (FlightMode.HOLD, FlightMode.POSCTL):
            self.hold_target = (state.north_m, state.east_m, 0.0 if state.on_ground else state.down_m)
        self._event(now, "Armed" + (" (forced)" if force else ""))
        return ACCEPTED

    def disarm(self, now: float, state: VehicleState, force: bool, reason: str) -> int:
        if not self.armed:
            return ACCEPTED
        if not state.on_ground and not force:
            self._event(now, "Disarming denied: not landed", mavlink.MAV_SEVERITY_CRITICAL)
            return TEMPORARILY_REJECTED
        self.armed, self.state_changed = False, True
        self._event(now, f"Disarmed ({reason})")
        if self.mode is not FlightMode.HOLD and state.on_ground:
            self.set_mode(FlightMode.HOLD, now, state, "disarmed on the ground")
        return ACCEPTED

    # ----------------------------------------------------------------- commands
    def handle_command(self, command: int, p: tuple[float, ...], now: float, state: VehicleState) -> int:
        """Execute one MAV_CMD with params p[0..6] (= param1..param7); returns a MAV_RESULT.

        Repeating a command (a retransmission) gives the same result and no second effect.
        """
        if command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            force = as_int(p[1]) == FORCE_MAGIC
            if p[0] == 1:
                return self.arm(now, state, force)
            if p[0] == 0:
                return self.disarm(now, state, force, "command")
            return DENIED
        if command == mavlink.MAV_CMD_NAV_TAKEOFF:
            return self._takeoff(p[6], now, state)
        if command == mavlink.MAV_CMD_NAV_LAND:
            return self.set_mode(FlightMode.LAND, now, state, "NAV_LAND")
        if command == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return self.set_mode(FlightMode.RTL, now, state, "NAV_RETURN_TO_LAUNCH")
        if command == mavlink.MAV_CMD_DO_SET_MODE:
            if not as_int(p[0], 0) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
                return DENIED  # PX4 only understands custom modes
            main, sub = as_int(p[1]), as_int(p[2], 0)
            mode = FlightMode.from_main_sub(main, sub)
            if mode is None:
                self._event(now, f"mode main={main} sub={sub} is not emulated", mavlink.MAV_SEVERITY_WARNING)
                return DENIED
            if mode is FlightMode.TAKEOFF:
                self.takeoff_alt_m = self.params["MIS_TAKEOFF_ALT"]
            return self.set_mode(mode, now, state, "DO_SET_MODE")
        if command == mavlink.MAV_CMD_SET_CAMERA_ZOOM:
            return self._zoom(as_int(p[0]), p[1], now)
        return UNSUPPORTED

    def _takeoff(self, altitude_amsl: float, now: float, state: VehicleState) -> int:
        if not self.armed:
            self._event(now, "Takeoff denied: disarmed", mavlink.MAV_SEVERITY_CRITICAL)
            return TEMPORARILY_REJECTED
        # PX4 reads param7 as an altitude above mean sea level and never takes off lower than
        # MIS_TAKEOFF_ALT above home (a relative altitude such as MAVProxy's "takeoff 10" ends up there).
        minimum = self.params["MIS_TAKEOFF_ALT"]
        target = altitude_amsl - self.home_alt_m if math.isfinite(altitude_amsl) else minimum
        if target < minimum:
            self._event(now, f"Using minimum takeoff altitude: {minimum:.2f} m", mavlink.MAV_SEVERITY_CRITICAL)
            target = minimum
        self.takeoff_alt_m = target
        if self.mode is FlightMode.TAKEOFF:  # a repeat (or a new altitude) while climbing
            self.hold_target = (self.hold_target[0], self.hold_target[1], -target)
            return ACCEPTED
        return self.set_mode(FlightMode.TAKEOFF, now, state, f"NAV_TAKEOFF to {target:.1f} m")

    def _zoom(self, zoom_type: int, value: float, now: float) -> int:
        if zoom_type == mavlink.ZOOM_TYPE_RANGE and 0.0 <= value <= 100.0:
            self.zoom_percent = value
        elif zoom_type == mavlink.ZOOM_TYPE_STEP and math.isfinite(value):
            self.zoom_percent = min(100.0, max(0.0, self.zoom_percent + 10.0 * value))
        else:
            return DENIED
        self._event(now, f"camera zoom {self.zoom_percent:.0f} %")
        return ACCEPTED

    # ----------------------------------------------------------------- offboard setpoints
    def handle_setpoint(self, now: float, state: VehicleState, frame: int, mask: int,
                        position: tuple[float, float, float], velocity: tuple[float, float, float],
                        yaw: float, yaw_rate: float) -> bool:
        """Accept one SET_POSITION_TARGET_LOCAL_NED; unsupported ones are counted by reason and ignored."""
        reason = self._setpoint_problem(frame, mask)
        is_velocity = (mask & MASK_POSITION) == MASK_POSITION
        values = velocity if is_velocity else position
        use_yaw = not mask & MASK_YAW
        use_rate = not use_yaw and not mask & MASK_YAW_RATE
        if reason is None and not all(math.isfinite(v) for v in values):
            reason = "non-finite value"
        if reason is None and ((use_yaw and not math.isfinite(yaw)) or (use_rate and not math.isfinite(yaw_rate))):
            reason = "non-finite yaw"
        if reason is not None:
            self.setpoints_ignored[reason] += 1
            return False
        north, east, down = values
        if frame == mavlink.MAV_FRAME_BODY_NED:  # x forward, y right: rotate by the current heading
            c, s = math.cos(state.yaw_rad), math.sin(state.yaw_rad)
            north, east = c * north - s * east, s * north + c * east
            if not is_velocity:  # a body-frame position is an offset from where the vehicle is now
                north, east, down = north + state.north_m, east + state.east_m, down + state.down_m
        if is_velocity:
            north, east, down = self._clamp_velocity(north, east, down)
        if self.setpoint is None or now - self.setpoint.time_s > STREAM_MAX_GAP_S:
            self.stream_start_s = now
        self.setpoint = Setpoint(now, is_velocity, north, east, down,
                                 yaw if use_yaw else None,
                                 self._clamp_yaw_rate(yaw_rate) if use_rate else None)
        self.setpoints_accepted += 1
        return True

    @staticmethod
    def _setpoint_problem(frame: int, mask: int) -> str | None:
        if frame not in (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_NED):
            return f"frame {frame}"
        if mask & MASK_ACCELERATION != MASK_ACCELERATION:
            return "acceleration/force setpoint"
        position_bits, velocity_bits = mask & MASK_POSITION, mask & MASK_VELOCITY
        if position_bits not in (0, MASK_POSITION) or velocity_bits not in (0, MASK_VELOCITY):
            return f"partial type_mask {mask}"
        if (position_bits == 0) == (velocity_bits == 0):
            return f"type_mask {mask}: need exactly one of position or velocity"
        return None

    def _clamp_velocity(self, north: float, east: float, down: float) -> tuple[float, float, float]:
        limit = self.params["MPC_XY_VEL_MAX"]
        speed = math.hypot(north, east)
        if speed > limit:
            north, east = north * limit / speed, east * limit / speed
        down = min(max(down, -self.params["MPC_Z_VEL_MAX_UP"]), self.params["MPC_Z_VEL_MAX_DN"])
        return north, east, down

    def _clamp_yaw_rate(self, rate: float) -> float:
        limit = math.radians(self.params["MPC_YAWRAUTO_MAX"])
        return min(max(rate, -limit), limit)

    # ----------------------------------------------------------------- the control loop
    def guidance(self, now: float, state: VehicleState) -> VelocityCommand:
        """Run failsafes and auto-disarm, then return this tick's velocity command for the dynamics."""
        if not self.armed:
            return HOVER
        self._auto_disarm(now, state)
        self._check_failsafes(now, state)
        if not self.armed:
            return HOVER
        mode = self.mode
        if mode is FlightMode.OFFBOARD:
            return self._offboard_command(state)
        if mode is FlightMode.TAKEOFF:
            north, east, down = self.hold_target
            if abs(state.down_m - down) < ARRIVED_RADIUS_M:
                self.set_mode(FlightMode.HOLD, now, state, "takeoff complete")
                self.hold_target = (north, east, down)  # hold the takeoff altitude, not where we were
            return velocity_toward(state, north, east, down, self.airframe,
                                   speed_xy_mps=self.params["MPC_XY_CRUISE"], speed_z_mps=self.params["MPC_TKO_SPEED"])
        if mode is FlightMode.LAND:
            return self._landing_command(state, self.hold_target[0], self.hold_target[1])
        if mode is FlightMode.RTL:
            return self._rtl_command(state)
        # HOLD and POSCTL (sticks centred): keep the captured position; on the ground stay down.
        north, east, down = self.hold_target
        if state.on_ground and down >= 0.0:
            return HOVER
        return velocity_toward(state, north, east, down, self.airframe, speed_xy_mps=self.params["MPC_XY_CRUISE"])

    def _offboard_command(self, state: VehicleState) -> VelocityCommand:
        sp = self.setpoint
        assert sp is not None  # OFFBOARD is only entered with a live stream
        if sp.is_velocity:
            return VelocityCommand(sp.north, sp.east, sp.down, sp.yaw_rad, sp.yaw_rate_rad_s)
        command = velocity_toward(state, sp.north, sp.east, sp.down, self.airframe,
                                  speed_xy_mps=self.params["MPC_XY_VEL_MAX"])
        return VelocityCommand(command.north_mps, command.east_mps, command.down_mps, sp.yaw_rad, sp.yaw_rate_rad_s)

    def _landing_command(self, state: VehicleState, north: float, east: float) -> VelocityCommand:
        """Descend over (north, east), slowing from MPC_Z_V_AUTO_DN to MPC_LAND_SPEED between ALT1 and ALT2."""
        alt = -state.down_m
        fast, slow = self.params["MPC_Z_V_AUTO_DN"], self.params["MPC_LAND_SPEED"]
        alt1, alt2 = self.params["MPC_LAND_ALT1"], self.params["MPC_LAND_ALT2"]
        if alt >= alt1:
            speed = fast
        elif alt <= alt2 or alt1 <= alt2:
            speed = slow
        else:
            speed = slow + (fast - slow) * (alt - alt2) / (alt1 - alt2)
        horizontal = velocity_toward(state, north, east, state.down_m, self.airframe,
                                     speed_xy_mps=self.params["MPC_XY_CRUISE"])
        return VelocityCommand(horizontal.north_mps, horizontal.east_mps, speed)

    def _rtl_command(self, state: VehicleState) -> VelocityCommand:
        """Climb to RTL_RETURN_ALT if lower, fly home at MPC_XY_CRUISE, then land there."""
        if self.rtl_landing or state.on_ground:
            return self._landing_command(state, 0.0, 0.0)
        return_down = min(state.down_m, -self.params["RTL_RETURN_ALT"])
        if state.down_m - return_down > ARRIVED_RADIUS_M:  # still climbing
            return velocity_toward(state, state.north_m, state.east_m, return_down, self.airframe,
                                   speed_xy_mps=0.0, speed_z_mps=self.params["MPC_Z_VEL_MAX_UP"])
        if math.hypot(state.north_m, state.east_m) < 1.0:
            self.rtl_landing = True
            return self._landing_command(state, 0.0, 0.0)
        return velocity_toward(state, 0.0, 0.0, state.down_m, self.airframe, speed_xy_mps=self.params["MPC_XY_CRUISE"])

    def _auto_disarm(self, now: float, state: VehicleState) -> None:
        if not state.on_ground:
            self.has_flown, self.ground_since_s = True, None
            return
        if self.ground_since_s is None:
            self.ground_since_s = now
        if self.has_flown:
            delay, why = self.params["COM_DISARM_LAND"], "landed"
        else:
            delay, why = self.params["COM_DISARM_PRFLT"], "no takeoff after arming"
        if delay >= 0 and now - self.ground_since_s >= delay and now - self.armed_at_s >= delay:
            self.disarm(now, state, force=False, reason=f"auto-disarm: {why}")

    def _check_failsafes(self, now: float, state: VehicleState) -> None:
        if self.mode is FlightMode.OFFBOARD:
            last = self.setpoint.time_s if self.setpoint else -math.inf
            if now - last > self.params["COM_OF_LOSS_T"]:
                action = FAILSAFE_MODES.get(int(self.params["COM_OBL_RC_ACT"]), FlightMode.HOLD)
                self._event(now, f"Failsafe: offboard setpoints lost for {now - last:.1f} s, "
                                 f"switching to {action.name}", mavlink.MAV_SEVERITY_CRITICAL)
                self.set_mode(action, now, state, "offboard loss failsafe")
        if state.on_ground:
            return
        fraction = state.battery_wh / self.airframe.battery_capacity_wh
        if fraction <= self.params["BAT_EMERGEN_THR"] and self.battery_failsafe != "emergency":
            self.battery_failsafe = "emergency"
            self._event(now, f"Failsafe: battery {fraction:.0%}, landing", mavlink.MAV_SEVERITY_EMERGENCY)
            self.set_mode(FlightMode.LAND, now, state, "battery emergency")
        elif fraction <= self.params["BAT_CRIT_THR"] and not self.battery_failsafe:
            self.battery_failsafe = "critical"
            self._event(now, f"Failsafe: battery {fraction:.0%}, returning", mavlink.MAV_SEVERITY_CRITICAL)
            self.set_mode(FlightMode.RTL, now, state, "battery critical")
