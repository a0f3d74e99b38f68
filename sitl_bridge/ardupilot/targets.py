"""How ArduCopter takes GUIDED targets from a companion computer: SET_POSITION_TARGET_LOCAL_NED and _GLOBAL_INT,
and "guided mode" mission items (MISSION_ITEM(_INT) with current = 2).

A mixin of :class:`sitl_bridge.ardupilot.autopilot.ArduCopter` (it uses the autopilot's mode, params, setpoint, hold
target and home); docs/sitl.md ("GUIDED", "ArduPilot: what was checked") lists the rules and their sources.
"""
from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.ardupilot.modes import CopterMode
from sitl_bridge.autopilot_base import (
    ABOVE_HOME_FRAMES,
    AMSL_FRAMES,
    MASK_ACCELERATION,
    MASK_FORCE,
    MASK_POSITION,
    MASK_VELOCITY,
    MASK_YAW,
    MASK_YAW_RATE,
    TERRAIN_FRAMES,
    Setpoint,
    body_to_ned,
)
from sitl_bridge.multirotor import VehicleState

GUIDED_FRAMES = (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_OFFSET_NED, mavlink.MAV_FRAME_BODY_NED,
                 mavlink.MAV_FRAME_BODY_OFFSET_NED)
BODY_FRAMES = (mavlink.MAV_FRAME_BODY_NED, mavlink.MAV_FRAME_BODY_OFFSET_NED)
LOCATION_ALT_MAX_M = 83000  # AP_Common/Location.h: the largest altitude a Location's alt field can hold (m)


class GuidedTargets:
    """ArduCopter's intake of GUIDED targets: accepted ones become ``self.setpoint``; a refused one stops the
    vehicle (ModeGuided::init) and is counted by reason."""

    def handle_setpoint(self, now: float, state: VehicleState, frame: int, mask: int,
                        position: tuple[float, float, float], velocity: tuple[float, float, float],
                        yaw: float, yaw_rate: float) -> bool:
        """GCS_MAVLINK_Copter::handle_message_set_position_target_local_ned, in the simulator's frame."""
        if self.mode is not CopterMode.GUIDED:
            self.setpoints_ignored["not in GUIDED"] += 1
            return False
        use_pos, use_vel = not mask & MASK_POSITION, not mask & MASK_VELOCITY
        use_acc = not mask & MASK_ACCELERATION
        reason = None
        if frame not in GUIDED_FRAMES:
            reason = f"frame {frame}"
        elif mask & MASK_FORCE and use_acc:
            reason = "force setpoint"
        elif use_vel and not all(math.isfinite(v) and abs(v) <= 1000.0 for v in velocity):
            reason = "insane velocity"
        elif use_pos and not all(math.isfinite(v) for v in position):
            reason = "non-finite position"
        elif not use_pos and not use_vel:
            reason = "acceleration setpoint" if use_acc else "nothing to fly"
        if reason is not None:
            return self._stop(reason, state)
        body = frame in BODY_FRAMES
        yaw_rad = None if mask & MASK_YAW or not math.isfinite(yaw) else yaw + (state.yaw_rad if body else 0.0)
        yaw_rate_rad_s = None if mask & MASK_YAW_RATE or not math.isfinite(yaw_rate) else yaw_rate
        if use_pos:
            north, east, down = position
            if body:
                north, east = body_to_ned(north, east, state.yaw_rad)
            if frame != mavlink.MAV_FRAME_LOCAL_NED:  # offset and body frames are relative to the vehicle
                north, east, down = north + state.north_m, east + state.east_m, down + state.down_m
        else:
            north, east, down = velocity
            if body:
                north, east = body_to_ned(north, east, state.yaw_rad)
            north, east, down = self._clamp_velocity(north, east, down)
        self.setpoint = Setpoint(now, not use_pos, north, east, down, yaw_rad, yaw_rate_rad_s)
        self.taking_off, self.guided_timed_out = False, False  # a new target ends a takeoff
        return True

    def handle_global_setpoint(self, now: float, state: VehicleState, frame: int, mask: int,
                               position: tuple[int, int, float], velocity: tuple[float, float, float],
                               yaw: float, yaw_rate: float) -> bool:
        """GCS_MAVLINK_Copter::handle_message_set_position_target_global_int: in GUIDED only; a position needs a
        latitude/longitude in range (check_latlng) and a GLOBAL, GLOBAL_RELATIVE_ALT or (with terrain data, none
        here) GLOBAL_TERRAIN_ALT frame, else the vehicle stops; then as SET_POSITION_TARGET_LOCAL_NED."""
        if self.mode is not CopterMode.GUIDED:
            self.setpoints_ignored["not in GUIDED"] += 1
            return False
        local = (math.nan, math.nan, math.nan)
        if not mask & MASK_POSITION:
            lat_int, lon_int, _ = position
            target = (self.global_target(frame, *position) if abs(lat_int) <= 90e7 and abs(lon_int) <= 180e7
                      else "latitude/longitude out of range")
            if isinstance(target, str):
                return self._stop(target, state)
            local = target
        return self.handle_setpoint(now, state, mavlink.MAV_FRAME_LOCAL_NED, mask, local, velocity, yaw, yaw_rate)

    def handle_mission_item(self, current: int, command: int, frame: int, lat_int: int, lon_int: int, alt_m: float,
                            now: float, state: VehicleState) -> int:
        """A MISSION_ITEM(_INT) outside a mission upload, as GCS_MAVLINK::handle_mission_item takes it; returns the
        MISSION_ACK's MAV_MISSION_RESULT. current = 2 is a "guided mode" waypoint (DroneKit's ``simple_goto``,
        MAVProxy's ``guided`` with guided_use_reposition off): in GUIDED a NAV_WAYPOINT becomes the GUIDED position
        target (ModeAuto::do_guided, ModeGuided::set_destination), else MAV_MISSION_ERROR; current = 3 (an
        altitude change) is acknowledged and changes nothing (Copter's handle_change_alt_request is empty). Anything
        else needs a mission upload, which is not emulated: MAV_MISSION_ERROR."""
        if current not in (2, 3):
            return mavlink.MAV_MISSION_ERROR
        if command == mavlink.MAV_CMD_NAV_WAYPOINT:  # AP_Mission::mavlink_int_to_mission_cmd's checks
            if abs(lat_int) > 90e7:
                return mavlink.MAV_MISSION_INVALID_PARAM5_X
            if abs(lon_int) > 180e7:
                return mavlink.MAV_MISSION_INVALID_PARAM6_Y
            if not math.isfinite(alt_m) or abs(alt_m) >= LOCATION_ALT_MAX_M:
                return mavlink.MAV_MISSION_INVALID_PARAM7
            if frame == mavlink.MAV_FRAME_MISSION:  # taken as an altitude above mean sea level
                frame = mavlink.MAV_FRAME_GLOBAL
            if frame not in AMSL_FRAMES + ABOVE_HOME_FRAMES + TERRAIN_FRAMES:
                return mavlink.MAV_MISSION_UNSUPPORTED_FRAME
        if current == 3:
            return mavlink.MAV_MISSION_ACCEPTED
        if self.mode is not CopterMode.GUIDED or command != mavlink.MAV_CMD_NAV_WAYPOINT:
            return mavlink.MAV_MISSION_ERROR  # (ArduPilot also takes CONDITION_YAW here; not emulated)
        target = self.global_target(frame, lat_int, lon_int, alt_m)
        if isinstance(target, str):  # a terrain frame: set_destination fails without terrain data
            return mavlink.MAV_MISSION_ERROR
        if self.armed and not state.on_ground:
            self.setpoint = Setpoint(now, False, *target)
            self.taking_off, self.guided_timed_out = False, False
        return mavlink.MAV_MISSION_ACCEPTED

    def _stop(self, reason: str, state: VehicleState) -> bool:
        """A refused GUIDED target: ModeGuided::init(true), the vehicle stops where it is; counted by reason."""
        self.setpoints_ignored[reason] += 1
        self.setpoint, self.hold_target = None, (state.north_m, state.east_m, state.down_m)
        return False

    def _clamp_velocity(self, north: float, east: float, down: float) -> tuple[float, float, float]:
        """GUIDED velocities are limited like the position controller's: WPNAV_SPEED, _UP, _DN."""
        limit = self.params["WPNAV_SPEED"] / 100.0
        speed = math.hypot(north, east)
        if speed > limit:
            north, east = north * limit / speed, east * limit / speed
        down = min(max(down, -self.params["WPNAV_SPEED_UP"] / 100.0), self.params["WPNAV_SPEED_DN"] / 100.0)
        return north, east, down
