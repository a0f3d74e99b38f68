"""The PX4 personality of the simulated vehicle: its state, what it reports, Commander's mode switching, and the
control loop that runs the failsafes and picks each tick's velocity command.

No I/O and no MAVLink encoding here: the vehicle hands decoded commands and setpoints in, and asks
:meth:`Px4Autopilot.guidance` for the velocity command the dynamics should fly this tick. The rules live in the
mixins, one concern each: arming (``sitl_bridge.px4.arming``), commands (``sitl_bridge.px4.commands``), the modes'
velocity commands (``sitl_bridge.px4.guidance``), offboard setpoints (``sitl_bridge.px4.offboard``), Mission mode
(``sitl_bridge.px4.mission``), the geofence (``sitl_bridge.px4.geofence``), rally points
(``sitl_bridge.px4.rally``) and the failsafes (``sitl_bridge.px4.failsafes``). ``docs/sitl.md`` lists the
differences and the PX4 sources checked.
"""
from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from missions.geodesy import LocalFrame
from sitl_bridge.autopilot_base import ACCEPTED, ARRIVED_RADIUS_M, TEMPORARILY_REJECTED, AutopilotBase, FlightStatus
from sitl_bridge.dynamics import velocity_toward
from sitl_bridge.multirotor import HOVER, MultirotorParams, VehicleState, VelocityCommand
from sitl_bridge.params import ParameterStore
from sitl_bridge.px4.arming import Px4Arming
from sitl_bridge.px4.commands import MISSION_PLANNER_COMPONENT, Px4Commands
from sitl_bridge.px4.failsafes import Px4Failsafes
from sitl_bridge.px4.geofence import Px4Geofence
from sitl_bridge.px4.guidance import Px4Guidance
from sitl_bridge.px4.mission import Px4MissionMode
from sitl_bridge.px4.modes import FlightMode, base_mode
from sitl_bridge.px4.offboard import OffboardSetpoints
from sitl_bridge.px4.orbit import Orbit
from sitl_bridge.px4.rally import Px4RallyPoints

REJECT_PRINT_INTERVAL_S = 1.0  # Commander::printRejectMode tells a ground station at most once a second
FLIGHT_SW_VERSION = (1 << 24) | (14 << 16) | (0 << 8) | 255  # reported as PX4 v1.14.0, official release
# The capabilities we really have (PX4 claims more: FTP, ...; we do not implement those). MAVSDK refuses every
# mission transfer with a vehicle whose AUTOPILOT_VERSION lacks MISSION_INT (system_impl.cpp).
CAPABILITIES = (mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
                | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
                | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
                | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2)

FAILSAFE_MODES = {0: FlightMode.POSCTL, 3: FlightMode.RTL, 4: FlightMode.LAND, 5: FlightMode.HOLD}
PHASE_OF_MODE = {FlightMode.OFFBOARD: "guided", FlightMode.HOLD: "holding", FlightMode.POSCTL: "holding",
                 FlightMode.ORBIT: "holding", FlightMode.TAKEOFF: "taking_off", FlightMode.RTL: "returning",
                 FlightMode.LAND: "landing", FlightMode.MISSION: "mission"}


class Px4Autopilot(Px4Commands, Px4Arming, Px4Guidance, OffboardSetpoints, Px4MissionMode, Px4Geofence,
                   Px4RallyPoints, Px4Failsafes, AutopilotBase):
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
            self.rtl_destination = self.closest_safe_point(state)  # RTL::on_activation
        self._event(now, f"mode {mode.name} ({reason})", broadcast=False)  # PX4 announces no mode change in text
        if mode is FlightMode.MISSION and self.armed:
            self._start_mission(now, state)
        return ACCEPTED


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
