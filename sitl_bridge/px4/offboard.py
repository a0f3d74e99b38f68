"""How PX4 takes offboard setpoints (SET_POSITION_TARGET_LOCAL_NED): which frames and type masks, the clamps.

A mixin of :class:`sitl_bridge.px4.autopilot.Px4Autopilot` (it uses the autopilot's params and stores ``setpoint``);
docs/sitl.md ("Offboard, as PX4 does it") lists the rules.
"""
from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.autopilot_base import (
    MASK_ACCELERATION,
    MASK_POSITION,
    MASK_VELOCITY,
    MASK_YAW,
    MASK_YAW_RATE,
    Setpoint,
    body_to_ned,
)
from sitl_bridge.multirotor import VehicleState

PX4_GLOBAL_FRAMES = (mavlink.MAV_FRAME_GLOBAL_INT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                     mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT)


class OffboardSetpoints:
    """PX4's intake of offboard setpoints: accepted ones become ``self.setpoint``, others are counted by reason."""

    def handle_setpoint(self, now: float, state: VehicleState, frame: int, mask: int,
                        position: tuple[float, float, float], velocity: tuple[float, float, float],
                        yaw: float, yaw_rate: float) -> bool:
        """Accept one SET_POSITION_TARGET_LOCAL_NED; unsupported ones are counted by reason and ignored."""
        reason = self._setpoint_problem(frame, mask)
        is_velocity = (mask & MASK_POSITION) == MASK_POSITION
        # position + velocity (MAVSDK's set_position_velocity_ned): PX4 flies the position with the velocity as
        # the position controller's feed-forward
        with_feedforward = not is_velocity and not mask & MASK_VELOCITY
        values = velocity if is_velocity else position
        use_yaw = not mask & MASK_YAW
        use_rate = not use_yaw and not mask & MASK_YAW_RATE
        if reason is None and not all(math.isfinite(v) for v in values + (velocity if with_feedforward else ())):
            reason = "non-finite value"
        if reason is None and ((use_yaw and not math.isfinite(yaw)) or (use_rate and not math.isfinite(yaw_rate))):
            reason = "non-finite yaw"
        if reason is not None:
            self.setpoints_ignored[reason] += 1
            return False
        north, east, down = values
        if frame == mavlink.MAV_FRAME_BODY_NED:  # x forward, y right: rotate by the current heading
            north, east = body_to_ned(north, east, state.yaw_rad)
            if not is_velocity:  # a body-frame position is an offset from where the vehicle is now
                north, east, down = north + state.north_m, east + state.east_m, down + state.down_m
        if is_velocity:
            north, east, down = self._clamp_velocity(north, east, down)
        self.setpoint = Setpoint(now, is_velocity, north, east, down,
                                 yaw if use_yaw else None,
                                 self._clamp_yaw_rate(yaw_rate) if use_rate else None,
                                 tuple(velocity) if with_feedforward else None)
        return True

    def handle_global_setpoint(self, now: float, state: VehicleState, frame: int, mask: int,
                               position: tuple[int, int, float], velocity: tuple[float, float, float],
                               yaw: float, yaw_rate: float) -> bool:
        """SET_POSITION_TARGET_GLOBAL_INT as PX4's mavlink_receiver takes it: a position (x, y and z all used) in
        MAV_FRAME_GLOBAL_INT (altitude above mean sea level) or GLOBAL_RELATIVE_ALT_INT (above home) is made local,
        in GLOBAL_TERRAIN_ALT_INT it needs terrain data (none here), other frames are refused; the rest (masks,
        velocity in NED, yaw) as for SET_POSITION_TARGET_LOCAL_NED."""
        local = (math.nan, math.nan, math.nan)
        if not mask & MASK_POSITION:
            target = (self.global_target(frame, *position) if frame in PX4_GLOBAL_FRAMES else f"frame {frame}")
            if isinstance(target, str):
                self.setpoints_ignored[target] += 1
                return False
            local = target
        return self.handle_setpoint(now, state, mavlink.MAV_FRAME_LOCAL_NED, mask, local, velocity, yaw, yaw_rate)

    @staticmethod
    def _setpoint_problem(frame: int, mask: int) -> str | None:
        if frame not in (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_NED):
            return f"frame {frame}"
        if mask & MASK_ACCELERATION != MASK_ACCELERATION:
            return "acceleration/force setpoint"
        position_bits, velocity_bits = mask & MASK_POSITION, mask & MASK_VELOCITY
        if position_bits not in (0, MASK_POSITION) or velocity_bits not in (0, MASK_VELOCITY):
            return f"partial type_mask {mask}"
        if position_bits and velocity_bits:
            return f"type_mask {mask}: neither position nor velocity"
        if not position_bits and not velocity_bits and frame != mavlink.MAV_FRAME_LOCAL_NED:
            return f"type_mask {mask}: position + velocity only in MAV_FRAME_LOCAL_NED"
        return None

    def _clamp_velocity(self, north: float, east: float, down: float) -> tuple[float, float, float]:
        limit = self.params["MPC_XY_VEL_MAX"]
        speed = math.hypot(north, east)
        if speed > limit:
            north, east = north * limit / speed, east * limit / speed
        down = min(max(down, -self.params["MPC_Z_VEL_MAX_UP"]), self.params["MPC_Z_VEL_MAX_DN"])
        return north, east, down

    def _clamp_yaw_rate(self, rate: float) -> float:
        # Since PX4 1.13 offboard setpoints reach the controllers without a flight task, so FlightTaskAuto's
        # MPC_YAWRAUTO_MAX does not apply; the attitude controller's MC_YAWRATE_MAX does (the airframe's own
        # yaw rate limit, 60 deg/s by default, comes after it in the dynamics).
        limit = math.radians(self.params["MC_YAWRATE_MAX"])
        return min(max(rate, -limit), limit)
