"""PX4-flavoured autopilot logic: arming, modes, commands, offboard rules and failsafes.

No I/O and no MAVLink encoding here: the vehicle hands decoded commands and setpoints in, and asks
:meth:`Px4Autopilot.guidance` for the velocity command the dynamics should fly this tick. What PX4 does and
why we copy it is noted where it matters; ``docs/sitl.md`` lists the differences and the PX4 sources checked.
"""
from __future__ import annotations

import dataclasses
import math

from pymavlink.dialects.v20 import common as mavlink

from missions.geodesy import LocalFrame
from sitl_bridge.autopilot_base import (
    ACCEPTED, ARRIVED_RADIUS_M, DENIED, FAILED, TEMPORARILY_REJECTED, UNSUPPORTED, AutopilotBase, AutopilotEvent,
    FlightStatus, Setpoint, as_int)
from sitl_bridge.dynamics import velocity_toward
from sitl_bridge.px4.geofence import Px4Geofence
from sitl_bridge.multirotor import HOVER, MultirotorParams, VehicleState, VelocityCommand
from sitl_bridge.params import ParameterStore
from sitl_bridge.px4.failsafes import (
    BATTERY_TEXTS, CRITICAL, EMERGENCY, NONE, Px4Failsafes, battery_warning_level)
from sitl_bridge.px4.mission import Px4MissionMode
from sitl_bridge.px4.modes import FlightMode, base_mode
from sitl_bridge.px4.offboard import OffboardSetpoints
from sitl_bridge.px4.orbit import Orbit

__all__ = ["ACCEPTED", "DENIED", "FAILED", "TEMPORARILY_REJECTED", "UNSUPPORTED", "Px4Autopilot", "AutopilotEvent",
           "Setpoint", "as_int"]

FORCE_MAGIC = 21196  # MAV_CMD_COMPONENT_ARM_DISARM param2: arm/disarm without checks
MISSION_PLANNER_COMPONENT = 190  # PX4 prints "Switching to ... not available" only for DO_SET_MODE from this one
REJECT_PRINT_INTERVAL_S = 1.0  # ... and at most once a second (Commander::printRejectMode)
FLIGHT_SW_VERSION = (1 << 24) | (14 << 16) | (0 << 8) | 255  # reported as PX4 v1.14.0, official release
# The capabilities we really have (PX4 claims more: FTP, ...; we do not implement those). MAVSDK refuses every
# mission transfer with a vehicle whose AUTOPILOT_VERSION lacks MISSION_INT (system_impl.cpp).
CAPABILITIES = (mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
                | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
                | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
                | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2)

INT32_MAX = 2**31 - 1  # COMMAND_INT x and y both INT32_MAX: no position given (mavlink_receiver.cpp)
NAN_AS_INT = 0x7FF80000  # ... both this: a NaN sent as an int by mistake, DENIED
REPOSITION_CHANGE_MODE = 1  # MAV_DO_REPOSITION_FLAGS_CHANGE_MODE, the only flag PX4 supports

BATTERY_FAILURES = {CRITICAL: "battery below BAT_CRIT_THR", EMERGENCY: "battery below BAT_EMERGEN_THR"}
FAILSAFE_MODES = {0: FlightMode.POSCTL, 3: FlightMode.RTL, 4: FlightMode.LAND, 5: FlightMode.HOLD}
PHASE_OF_MODE = {FlightMode.OFFBOARD: "guided", FlightMode.HOLD: "holding", FlightMode.POSCTL: "holding",
                 FlightMode.ORBIT: "holding", FlightMode.TAKEOFF: "taking_off", FlightMode.RTL: "returning",
                 FlightMode.LAND: "landing", FlightMode.MISSION: "mission"}


class Px4Autopilot(OffboardSetpoints, Px4MissionMode, Px4Geofence, Px4Failsafes, AutopilotBase):
    """Modes, arming and command handling of one simulated PX4 multirotor."""

    PARAMS_BYTEWISE = True
    STATUSTEXT_ID_PER_TEXT = True
    MAV_AUTOPILOT = mavlink.MAV_AUTOPILOT_PX4
    CAPABILITIES = CAPABILITIES
    FLIGHT_SW_VERSION = FLIGHT_SW_VERSION

    def __init__(self, params: ParameterStore, airframe: MultirotorParams, frame: LocalFrame):
        super().__init__(params, airframe, frame)
        self.home_alt_m = frame.home.alt_m  # AMSL (moves with home); NAV_TAKEOFF's param7 is an AMSL altitude in PX4
        self.mode = FlightMode.HOLD
        self.hold_target: tuple[float, float, float] = (0.0, 0.0, 0.0)
        # Navigator's cruising speed (a reposition's or DO_CHANGE_SPEED's ground speed; None: MPC_XY_CRUISE), used by
        # HOLD and RTL; reset on every mode change
        self.cruise_speed_mps: float | None = None
        self.hold_yaw_rad: float | None = None  # a reposition's heading (None: hold the heading)
        self.orbit: Orbit | None = None  # in ORBIT; None after a refused radius (PX4's failsafe task: hold)
        self.takeoff_alt_m = 0.0
        self.rtl_landing = False
        self.armed_at_s = 0.0
        self.has_flown = False
        self.ground_since_s: float | None = None
        self._last_reject_print_s = -math.inf
        # In the offboard-loss fallback: the user's intended mode is still OFFBOARD (Failsafe::checkModeFallback
        # leaves it), so once setpoints flow again the fallback clears and the vehicle is back in OFFBOARD.
        self.offboard_fallback = False
        self.mission_reached_news = []

    # ----------------------------------------------------------------- what the vehicle reports
    def offboard_signal_lost(self, now: float) -> bool:
        """PX4's offboard "proof of life" (OffboardChecks::checkAndReport): the last setpoint is older than
        COM_OF_LOSS_T, or there is none, or the local position/velocity it needs is invalid (no GPS here).
        The same rule refuses the switch into OFFBOARD and triggers the offboard-loss failsafe."""
        last = self.setpoint.time_s if self.setpoint is not None else -math.inf
        return now - last > self.params["COM_OF_LOSS_T"] or not self.gps_ok

    def heartbeat_fields(self) -> tuple[int, int, int, int]:
        status = mavlink.MAV_STATE_ACTIVE if self.armed else mavlink.MAV_STATE_STANDBY
        return self.MAV_AUTOPILOT, base_mode(self.mode, self.armed), self.mode.custom_mode, status

    @property
    def status(self) -> FlightStatus:
        phase = PHASE_OF_MODE[self.mode]
        if self.mode is FlightMode.RTL and self.rtl_landing:
            phase = "landing"
        if not self.armed or (self.ground_since_s is not None and phase in ("holding", "landing")):
            phase = "on_ground"
        return FlightStatus(self.armed, self.mode.name, phase, self.setpoint.time_s if self.setpoint else None,
                            self.params["COM_OF_LOSS_T"])

    def landed_state(self, state: VehicleState) -> int:
        """MAV_LANDED_STATE for EXTENDED_SYS_STATE."""
        if state.on_ground:
            return mavlink.MAV_LANDED_STATE_ON_GROUND
        if self.mode is FlightMode.TAKEOFF:
            return mavlink.MAV_LANDED_STATE_TAKEOFF
        if self.mode is FlightMode.MISSION and self.mission_setpoint == "takeoff":
            return mavlink.MAV_LANDED_STATE_TAKEOFF
        if (self.mode is FlightMode.LAND or (self.mode is FlightMode.RTL and self.rtl_landing)
                or (self.mode is FlightMode.MISSION and self.mission_setpoint == "land")):
            return mavlink.MAV_LANDED_STATE_LANDING
        return mavlink.MAV_LANDED_STATE_IN_AIR

    def prearm_failure(self, state: VehicleState) -> str | None:
        """Why arming is refused, or None when the pre-arm checks pass."""
        if not self.gps_ok:
            return "no GPS fix"
        level = battery_warning_level(self.battery_fraction(state), self.params)
        if level in BATTERY_FAILURES:  # batteryCheck.cpp: critical or worse affects every mode
            return BATTERY_FAILURES[level]
        if self.mode is FlightMode.MISSION and not self.check_mission(0.0, state, announce=False):
            return "No valid mission available"  # modeCheck.cpp: an event only, as "No valid global position"
        return next(iter(self.geofence_violations(state)), None)

    # ----------------------------------------------------------------- modes and arming
    def set_mode(self, mode: FlightMode, now: float, state: VehicleState, reason: str,
                 source_component: int | None = None) -> int:
        """Switch mode as PX4's commander would; returns a MAV_RESULT. ``source_component``: the requester's
        MAVLink component for external requests (None: the autopilot's own switch, e.g. a failsafe)."""
        # Commander: a mode that cannot run (offboard_control_signal_lost; armed, auto_mission_missing) gets
        # TEMPORARILY_REJECTED, and printRejectMode() tells a ground station (component 190) once a second.
        cannot_run = {FlightMode.OFFBOARD: lambda: self.offboard_signal_lost(now),
                      FlightMode.MISSION: lambda: self.armed and not self.check_mission(now, state, announce=False)}
        if mode in cannot_run and self.mode is not mode and cannot_run[mode]():
            if (source_component == MISSION_PLANNER_COMPONENT
                    and now - self._last_reject_print_s > REJECT_PRINT_INTERVAL_S):
                self._last_reject_print_s = now
                self._event(now, f"Switching to {mode.name.capitalize()} is currently not available\t",
                            mavlink.MAV_SEVERITY_CRITICAL)
            return TEMPORARILY_REJECTED
        self.offboard_fallback = False  # any switch but the fallback's own ends it (the caller sets it after)
        self._forget_failsafe_actions()  # ... and is a user takeover of a failsafe's action (the same rule)
        if mode is self.mode:
            return ACCEPTED
        if self.mode is FlightMode.MISSION:
            # MissionBase::on_inactivation; it also sets seq_reached to -1 but does not publish it, so MISSION_CURRENT
            # goes on seeing the last item reached (PAUSED) until the mission starts again
            self._climb = None
        self.mode = mode
        self.state_changed = True
        self.cruise_speed_mps = self.hold_yaw_rad = None  # Navigator resets the cruising speed on a mode change
        if mode in (FlightMode.HOLD, FlightMode.POSCTL, FlightMode.ORBIT):
            self.hold_target = (state.north_m, state.east_m, 0.0 if state.on_ground else state.down_m)
            if mode is FlightMode.ORBIT:  # FlightTaskOrbit::activate: 1 m, 1 m/s, centred where the vehicle is
                self.orbit = Orbit(state.north_m, state.east_m, state.down_m, initial_yaw_rad=state.yaw_rad,
                                   yaw_behaviour=int(self.params["MC_ORBIT_YAW_MOD"]))
        elif mode is FlightMode.TAKEOFF:
            self.hold_target = (state.north_m, state.east_m, -self.takeoff_alt_m)
        elif mode is FlightMode.LAND:
            self.hold_target = (state.north_m, state.east_m, 0.0)
        elif mode is FlightMode.RTL:
            self.rtl_landing = False
        self._event(now, f"mode {mode.name} ({reason})", broadcast=False)  # PX4 announces no mode change in text
        if mode is FlightMode.MISSION and self.armed:
            self._start_mission(now, state)
        return ACCEPTED

    def arm(self, now: float, state: VehicleState, force: bool) -> int:
        if self.armed:
            return ACCEPTED
        failure = None if force else self.prearm_failure(state)
        if failure:
            self._refuse_arming(now, state, failure)
            return TEMPORARILY_REJECTED
        self.armed, self.state_changed = True, True
        self.armed_at_s, self.has_flown, self.ground_since_s = now, False, None
        self.battery_warning = NONE
        self._forget_failsafe_actions()
        if self.mode in (FlightMode.HOLD, FlightMode.POSCTL):
            self.hold_target = (state.north_m, state.east_m, 0.0 if state.on_ground else state.down_m)
        self._event(now, "Armed by external command\t")  # Commander::arm; forced or not, the same text
        if self.mode is FlightMode.MISSION:  # Navigator runs a mode only while armed: the mission starts now
            self._start_mission(now, state)
        if force:
            self._event(now, "forced: pre-arm checks skipped", broadcast=False)
        return ACCEPTED

    def _refuse_arming(self, now: float, state: VehicleState, failure: str) -> None:
        """Commander::arm: "Arming denied: Resolve system health failures first". The reason goes out as a
        STATUSTEXT only where its health check has a legacy mavlink_log text (geofenceCheck.cpp, batteryCheck.cpp);
        modeCheck.cpp's "No valid global position estimate" is an event only. The vehicle's log names it."""
        if failure.startswith("Geofence: "):
            self._event(now, failure, mavlink.MAV_SEVERITY_CRITICAL)
        elif failure in BATTERY_FAILURES.values():
            self._event(now, *BATTERY_TEXTS[battery_warning_level(self.battery_fraction(state), self.params)])
        self._event(now, f"arming refused: {failure}", broadcast=False)
        self._event(now, "Arming denied: Resolve system health failures first\t", mavlink.MAV_SEVERITY_CRITICAL)

    def disarm(self, now: float, state: VehicleState, force: bool, reason: str) -> int:
        if not self.armed:
            return ACCEPTED
        if not state.on_ground and not force:
            self._event(now, "Disarming denied: not landed", mavlink.MAV_SEVERITY_CRITICAL)
            return TEMPORARILY_REJECTED
        self.armed, self.state_changed, self.offboard_fallback = False, True, False
        self._disarmed_since_start = True
        self._forget_failsafe_actions()
        self._event(now, f"Disarmed by {reason}\t")  # Commander::disarm, arm_disarm_reason_str
        if self.mode is not FlightMode.HOLD and state.on_ground:
            self.set_mode(FlightMode.HOLD, now, state, "disarmed on the ground")
        return ACCEPTED

    # ----------------------------------------------------------------- commands
    def handle_command(self, command: int, p: tuple[float, ...], now: float, state: VehicleState,
                       source_component: int = MISSION_PLANNER_COMPONENT, frame: int | None = None) -> int:
        """Execute one MAV_CMD with params p[0..6] (= param1..param7); returns a MAV_RESULT.

        Repeating a command (a retransmission) gives the same result and no second effect. ``frame`` (of a
        COMMAND_INT) is not used by PX4's handling of the emulated commands.
        """
        if command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            force = as_int(p[1]) == FORCE_MAGIC
            if p[0] == 1:
                return self.arm(now, state, force)
            if p[0] == 0:
                return self.disarm(now, state, force, "external command")
            return DENIED
        if command == mavlink.MAV_CMD_NAV_TAKEOFF:
            return self._takeoff(p[6], now, state)
        if command == mavlink.MAV_CMD_MISSION_START:
            return self._mission_start(p[0], now, state, source_component)
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
            return self.set_mode(mode, now, state, "DO_SET_MODE", source_component)
        if command == mavlink.MAV_CMD_SET_CAMERA_ZOOM:
            return self._zoom(as_int(p[0]), p[1], now)
        if command == mavlink.MAV_CMD_DO_REPOSITION:
            return self._reposition(p, frame, now, state)
        if command == mavlink.MAV_CMD_DO_ORBIT:
            return self._orbit(p, frame, now, state)
        if command == mavlink.MAV_CMD_DO_CHANGE_SPEED:  # Navigator: param2 > 0 sets the cruising speed, else resets
            self.cruise_speed_mps = p[1] if math.isfinite(p[1]) and p[1] > 0.0 else None
            return ACCEPTED
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

    def _reposition(self, p: tuple[float, ...], frame: int | None, now: float, state: VehicleState) -> int:
        """MAV_CMD_DO_REPOSITION (MAVSDK's goto_location) as PX4's Commander (the change-mode flag, then Hold) and
        Navigator (armed only: position, AMSL altitude, ground speed, heading in radians; NaN keeps the current
        one) split it; docs/sitl.md ("PX4: what was checked") has the sources and what is not emulated."""
        flags = as_int(p[1], 0)
        if flags != REPOSITION_CHANGE_MODE:
            return UNSUPPORTED
        result, place, take = self._place_command(FlightMode.HOLD, p, frame, now, state, "DO_REPOSITION")
        if not take:
            return result
        north, east = place or (state.north_m, state.east_m)
        down = self.down_of(p[6]) if math.isfinite(p[6]) else state.down_m
        self.hold_target = (north, east, down)
        self.cruise_speed_mps = p[0] if math.isfinite(p[0]) and p[0] > 0.0 else None
        self.hold_yaw_rad = p[3] if math.isfinite(p[3]) else None
        self._event(now, f"reposition to {north:.1f} m N, {east:.1f} m E, {-down:.1f} m up")
        return result

    def _orbit(self, p: tuple[float, ...], frame: int | None, now: float, state: VehicleState) -> int:
        """MAV_CMD_DO_ORBIT as PX4 splits it: Commander switches to Orbit (a position is needed), FlightTaskOrbit
        takes the parameters while flying (sitl_bridge.px4.orbit); out of range radius: the failsafe task holds."""
        result, place, take = self._place_command(FlightMode.ORBIT, p, frame, now, state, "DO_ORBIT")
        if not take or self.orbit is None:
            return result
        down = self.down_of(p[6]) if math.isfinite(p[6]) else None
        if not self.orbit.apply(p[0], p[1], p[2], place, down, state.yaw_rad, self.params["MC_ORBIT_RAD_MAX"]):
            self._event(now, "Orbit radius limit exceeded", mavlink.MAV_SEVERITY_CRITICAL)
            self.orbit = None
            self.hold_target = (state.north_m, state.east_m, state.down_m)
        return result

    def _place_command(self, mode: FlightMode, p: tuple[float, ...], frame: int | None, now: float,
                       state: VehicleState, reason: str) -> tuple[int, tuple[float, float] | None, bool]:
        """Commander's half of DO_REPOSITION and DO_ORBIT: param5/param6 as a place, a GPS fix, the switch to
        ``mode``. Returns (MAV_RESULT, the place in local NED or None when not given, whether the flight side
        takes the command's parameters: only armed and in the air). In a COMMAND_INT (mavlink_receiver.cpp,
        handle_message_command_int) x and y both INT32_MAX mean "not given", both 0x7FF80000 (a NaN sent as an
        int) are DENIED; a latitude beyond 90 degrees or a longitude beyond 180 is DENIED too."""
        lat, lon = p[4], p[5]
        if frame is not None:
            if lat == lon == NAN_AS_INT:
                return DENIED, None, False
            lat, lon = (math.nan, math.nan) if lat == lon == INT32_MAX else (lat / 1e7, lon / 1e7)
        if abs(lat) > 90.0 or abs(lon) > 180.0:  # not a place (a NaN compares False: "keep the position")
            return DENIED, None, False
        if not self.gps_ok:
            return TEMPORARILY_REJECTED, None, False
        result = self.set_mode(mode, now, state, reason)
        place = self.ned_of(lat, lon) if math.isfinite(lat) and math.isfinite(lon) else None
        return result, place, result == ACCEPTED and self.armed and not state.on_ground

    def handle_set_mode_message(self, base_mode: int, custom_mode: int, now: float, state: VehicleState) -> int | None:
        """SET_MODE: PX4 turns it into DO_SET_MODE internally and sends no ACK for the message."""
        mode = FlightMode.from_custom_mode(custom_mode)
        if mode is not None and base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            self.set_mode(mode, now, state, "SET_MODE")
        return None

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
        if mode is FlightMode.MISSION:
            return self._mission_command(now, state)
        if mode is FlightMode.ORBIT and self.orbit is not None and not state.on_ground:
            return self.orbit.command(state, self.airframe, self.params["MPC_XY_CRUISE"])
        return self._hold_command(state)

    def _hold_command(self, state: VehicleState) -> VelocityCommand:
        """HOLD, POSCTL (sticks centred), an orbit whose radius was refused and Mission mode's waits: keep the
        captured position (or fly to a reposition's); on the ground stay down."""
        north, east, down = self.hold_target
        if state.on_ground and down >= 0.0:
            return HOVER
        command = velocity_toward(state, north, east, down, self.airframe,
                                  speed_xy_mps=self.cruise_speed_mps or self.params["MPC_XY_CRUISE"])
        return command if self.hold_yaw_rad is None else dataclasses.replace(command, yaw_rad=self.hold_yaw_rad)

    def _offboard_command(self, state: VehicleState) -> VelocityCommand:
        sp = self.setpoint
        assert sp is not None  # OFFBOARD is only entered with a live stream
        if sp.is_velocity:
            return VelocityCommand(sp.north, sp.east, sp.down, sp.yaw_rad, sp.yaw_rate_rad_s)
        command = velocity_toward(state, sp.north, sp.east, sp.down, self.airframe,
                                  speed_xy_mps=self.params["MPC_XY_VEL_MAX"])
        north, east, down = command.north_mps, command.east_mps, command.down_mps
        if sp.feedforward is not None:  # PX4's PositionControl: P output + feed-forward, then the limits
            north, east, down = self._clamp_velocity(north + sp.feedforward[0], east + sp.feedforward[1],
                                                     down + sp.feedforward[2])
        return VelocityCommand(north, east, down, sp.yaw_rad, sp.yaw_rate_rad_s)

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
        """Climb to RTL_RETURN_ALT if lower, fly home at the cruising speed (MPC_XY_CRUISE), then land there."""
        home_n, home_e, _ = self.home_ned
        if self.rtl_landing or state.on_ground:
            return self._landing_command(state, home_n, home_e)
        return_down = min(state.down_m, -self.params["RTL_RETURN_ALT"])
        if state.down_m - return_down > ARRIVED_RADIUS_M:  # still climbing
            return velocity_toward(state, state.north_m, state.east_m, return_down, self.airframe,
                                   speed_xy_mps=0.0, speed_z_mps=self.params["MPC_Z_VEL_MAX_UP"])
        if math.hypot(state.north_m - home_n, state.east_m - home_e) < 1.0:
            self.rtl_landing = True
            return self._landing_command(state, home_n, home_e)
        return velocity_toward(state, home_n, home_e, state.down_m, self.airframe,
                               speed_xy_mps=self.cruise_speed_mps or self.params["MPC_XY_CRUISE"])

    def _auto_disarm(self, now: float, state: VehicleState) -> None:
        if not state.on_ground:
            self.has_flown, self.ground_since_s = True, None
            return
        if self.ground_since_s is None:
            self.ground_since_s = now
        if self.has_flown:
            delay, why = self.params["COM_DISARM_LAND"], "landing"
        else:
            delay, why = self.params["COM_DISARM_PRFLT"], "auto preflight disarming"
        if delay >= 0 and now - self.ground_since_s >= delay and now - self.armed_at_s >= delay:
            self.disarm(now, state, force=False, reason=why)

    def _check_failsafes(self, now: float, state: VehicleState) -> None:
        self._run_delayed_failsafe(now, state)
        if self.mode is FlightMode.OFFBOARD and self.offboard_signal_lost(now):
            last = self.setpoint.time_s if self.setpoint else -math.inf
            action = FAILSAFE_MODES.get(int(self.params["COM_OBL_RC_ACT"]), FlightMode.HOLD)
            why = f"offboard setpoints lost for {now - last:.1f} s" if self.gps_ok else "no position estimate"
            self._failsafe(now, state, action, why)  # a mode fallback: never delayed (takeover "Always")
            self.offboard_fallback = True
        elif self.offboard_fallback and not self.offboard_signal_lost(now):
            self._event(now, "Offboard setpoints back: the offboard-loss fallback cleared", broadcast=False)
            self.set_mode(FlightMode.OFFBOARD, now, state, "offboard fallback cleared")
        self._check_geofence(now, state)
        if not state.on_ground:
            self._check_battery(now, state)
