"""How ArduCopter's flight modes fly: the velocity command of a takeoff, GUIDED, LAND and RTL for one tick.

A mixin of :class:`sitl_bridge.ardupilot.autopilot.ArduCopter` (it uses the autopilot's params, setpoint, home and
RTL state); ``ArduCopter.guidance`` picks the mode's command every tick. The rules follow ArduCopter's
ModeGuided::velaccel_control_run (GUID_TIMEOUT), Mode::land_run_vertical_control and ModeRTL's states (climb,
return, loiter at home, final descent or land), as the methods' notes say.
"""
from __future__ import annotations

import math

from sitl_bridge.ardupilot.modes import CopterMode
from sitl_bridge.autopilot_base import ARRIVED_RADIUS_M
from sitl_bridge.dynamics import velocity_toward
from sitl_bridge.multirotor import VehicleState, VelocityCommand

HOME_REACHED_M = 1.0  # RTL's return leg ends this close to its target (horizontally)


class CopterGuidance:
    """The velocity commands of ArduCopter's takeoff, GUIDED, LAND and RTL."""

    def _takeoff_command(self, state: VehicleState) -> VelocityCommand:
        north, east, down = self.hold_target
        climb = self.params["WPNAV_SPEED_UP" if self.mode in (CopterMode.GUIDED, CopterMode.AUTO)
                            else "PILOT_SPEED_UP"] / 100.0
        if abs(state.down_m - down) < ARRIVED_RADIUS_M:
            self.taking_off = False  # complete; GUIDED and LOITER hold the takeoff point
        return velocity_toward(state, north, east, down, self.airframe,
                               speed_xy_mps=self.params["WPNAV_SPEED"] / 100.0, speed_z_mps=climb)

    def _guided_command(self, now: float, state: VehicleState, speed_xy: float) -> VelocityCommand:
        sp = self.setpoint
        if sp is None:
            return velocity_toward(state, *self.hold_target, self.airframe, speed_xy_mps=speed_xy)
        if not sp.is_velocity:
            cmd = velocity_toward(state, sp.north, sp.east, sp.down, self.airframe, speed_xy_mps=speed_xy)
            return VelocityCommand(cmd.north_mps, cmd.east_mps, cmd.down_mps, sp.yaw_rad, sp.yaw_rate_rad_s)
        if now - sp.time_s > max(self.params["GUID_TIMEOUT"], 0.1):  # ModeGuided::velaccel_control_run
            if not self.guided_timed_out:
                self.guided_timed_out, self.guided_timeouts = True, self.guided_timeouts + 1
            return VelocityCommand(0.0, 0.0, 0.0, sp.yaw_rad, None)
        return VelocityCommand(sp.north, sp.east, sp.down, sp.yaw_rad, sp.yaw_rate_rad_s)

    def _landing_command(self, now: float, state: VehicleState, north: float, east: float) -> VelocityCommand:
        """Mode::land_run_vertical_control: WPNAV_SPEED_DN (or LAND_SPEED_HIGH) high up, LAND_SPEED below
        LAND_ALT_LOW; a failsafe LAND first holds altitude for 4 s."""
        down = state.down_m
        if now >= self.land_pause_until_s:
            alt = self.home_ned[2] - state.down_m
            fast = self.params["LAND_SPEED_HIGH"] or self.params["WPNAV_SPEED_DN"]
            speed = (fast if alt > self.params["LAND_ALT_LOW"] / 100.0 else self.params["LAND_SPEED"]) / 100.0
        else:
            speed = 0.0
        horizontal = velocity_toward(state, north, east, down, self.airframe,
                                     speed_xy_mps=self.params["WPNAV_SPEED"] / 100.0)
        return VelocityCommand(horizontal.north_mps, horizontal.east_mps, speed)

    def _rtl_command(self, now: float, state: VehicleState) -> VelocityCommand:
        """ModeRTL: INITIAL_CLIMB, RETURN_HOME, LOITER_AT_HOME, then FINAL_DESCENT or LAND, over the return target
        (home or a rally point)."""
        (target_n, target_e), home_d = self.rtl_target, self.home_ned[2]
        speed_xy = (self.params["RTL_SPEED"] or self.params["WPNAV_SPEED"]) / 100.0
        if self.rtl_state == "climb":
            if state.down_m - self.rtl_return_down_m <= ARRIVED_RADIUS_M:
                self.rtl_state = "return"
            return velocity_toward(state, state.north_m, state.east_m, self.rtl_return_down_m, self.airframe,
                                   speed_xy_mps=0.0, speed_z_mps=self.params["WPNAV_SPEED_UP"] / 100.0)
        if self.rtl_state == "return":
            if math.hypot(state.north_m - target_n, state.east_m - target_e) < HOME_REACHED_M:
                self.rtl_state, self._rtl_loiter_since_s = "loiter", now
            return velocity_toward(state, target_n, target_e, self.rtl_return_down_m, self.airframe,
                                   speed_xy_mps=speed_xy)
        if self.rtl_state == "loiter" and now - self._rtl_loiter_since_s >= self.params["RTL_LOIT_TIME"] / 1000.0:
            self.rtl_state = "land" if self.params["RTL_ALT_FINAL"] <= 0 else "final"
        if self.rtl_state == "land":
            return self._landing_command(now, state, target_n, target_e)
        down = home_d - self.params["RTL_ALT_FINAL"] / 100.0 if self.rtl_state == "final" else self.rtl_return_down_m
        return velocity_toward(state, target_n, target_e, down, self.airframe, speed_xy_mps=speed_xy)
