"""How PX4's flight modes fly: the velocity command of Hold (and Position with centred sticks), Offboard, Land and
Return for one tick.

A mixin of :class:`sitl_bridge.px4.autopilot.Px4Autopilot` (it uses the autopilot's params, setpoint, hold target,
cruising speed, home and Return's destination); ``Px4Autopilot.guidance`` picks the mode's command every tick.
Land slows from MPC_Z_V_AUTO_DN to MPC_LAND_SPEED between MPC_LAND_ALT1 and MPC_LAND_ALT2 (the multicopter land
speed of ``FlightTaskAuto``); Return climbs to RTL_RETURN_ALT above its destination (home, or the rally point
``sitl_bridge.px4.rally`` chose), flies there at the cruising speed and lands (``RtlDirect``'s climb, return and
land, without the cone, the descent to RTL_DESCEND_ALT and the loiter before landing).
"""
from __future__ import annotations

import dataclasses
import math

from sitl_bridge.autopilot_base import ARRIVED_RADIUS_M
from sitl_bridge.dynamics import velocity_toward
from sitl_bridge.multirotor import HOVER, VehicleState, VelocityCommand


class Px4Guidance:
    """The velocity commands of PX4's Hold, Offboard, Land and Return."""

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
        """Climb to RTL_RETURN_ALT above the destination if lower, fly there at the cruising speed (MPC_XY_CRUISE),
        then land. The destination is home (the return altitude counted from the ground under it) or the rally point
        chosen when RTL began (counted from the rally point's altitude)."""
        if self.rtl_destination is None:
            dest_n, dest_e, dest_down = self.home_ned[0], self.home_ned[1], 0.0
        else:
            dest_n, dest_e, dest_down = self.rtl_destination
        if self.rtl_landing or state.on_ground:
            return self._landing_command(state, dest_n, dest_e)
        return_down = min(state.down_m, dest_down - self.params["RTL_RETURN_ALT"])
        if state.down_m - return_down > ARRIVED_RADIUS_M:  # still climbing
            return velocity_toward(state, state.north_m, state.east_m, return_down, self.airframe,
                                   speed_xy_mps=0.0, speed_z_mps=self.params["MPC_Z_VEL_MAX_UP"])
        if math.hypot(state.north_m - dest_n, state.east_m - dest_e) < 1.0:
            self.rtl_landing = True
            return self._landing_command(state, dest_n, dest_e)
        return velocity_toward(state, dest_n, dest_e, state.down_m, self.airframe,
                               speed_xy_mps=self.cruise_speed_mps or self.params["MPC_XY_CRUISE"])
