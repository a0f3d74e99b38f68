"""PX4's handling of COMMAND_LONG / COMMAND_INT and the SET_MODE message: what Commander and Navigator do with
each emulated MAV_CMD, and the MAV_RESULT it gets.

A mixin of :class:`sitl_bridge.px4.autopilot.Px4Autopilot` (it uses the autopilot's ``set_mode``, ``arm``,
``disarm``, Mission mode and orbit). Read in PX4-Autopilot: ``Commander::handle_command`` (arming, DO_SET_MODE,
DO_REPOSITION's change-mode flag, DO_ORBIT), ``mavlink_receiver.cpp`` ``handle_message_command_int`` (x/y as a place
or "not given"), ``navigator_main.cpp`` and ``loiter.cpp`` (the reposition target, DO_CHANGE_SPEED) and
``FlightTaskOrbit`` (the orbit's parameters); docs/sitl.md, "PX4: what was checked", has the details.
"""
from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.autopilot_base import ACCEPTED, DENIED, TEMPORARILY_REJECTED, UNSUPPORTED, as_int
from sitl_bridge.multirotor import VehicleState
from sitl_bridge.px4.modes import FlightMode

FORCE_MAGIC = 21196  # MAV_CMD_COMPONENT_ARM_DISARM param2: arm/disarm without checks
MISSION_PLANNER_COMPONENT = 190  # PX4 prints "Switching to ... not available" only for DO_SET_MODE from this one
INT32_MAX = 2**31 - 1  # COMMAND_INT x and y both INT32_MAX: no position given (mavlink_receiver.cpp)
NAN_AS_INT = 0x7FF80000  # ... both this: a NaN sent as an int by mistake, DENIED
REPOSITION_CHANGE_MODE = 1  # MAV_DO_REPOSITION_FLAGS_CHANGE_MODE, the only flag PX4 supports


class Px4Commands:
    """The MAV_CMDs the PX4 personality acts on (the rest are UNSUPPORTED) and the SET_MODE message."""

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
