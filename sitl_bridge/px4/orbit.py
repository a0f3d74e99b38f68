"""PX4's Orbit mode (MAV_CMD_DO_ORBIT, MAVSDK's ``action.do_orbit``): circle a point at a radius and speed.

As PX4's FlightTaskOrbit does it (src/modules/flight_mode_manager/tasks/Orbit/FlightTaskOrbit.cpp, read through the
search tools; docs/sitl.md, "PX4: what was checked"):

* the command's parameters: param1 the radius, its sign the direction (positive: clockwise seen from above),
  param2 the tangential speed, param3 the yaw behaviour, param5/param6 the centre's latitude/longitude, param7
  its altitude above mean sea level; a NaN keeps the orbit's current value (on entering the mode: 1 m, 1 m/s,
  MC_ORBIT_YAW_MOD, centred where the vehicle is, at its altitude);
* a radius outside [1 m, MC_ORBIT_RAD_MAX] is refused ("Orbit radius limit exceeded"); the speed is limited to
  10 m/s and to sqrt(2 m/s² × radius), the centripetal acceleration PX4 allows;
* off the circle (more than 1 m from the radius, or more than NAV_MC_ALT_RAD from the centre's altitude) the
  vehicle first flies to the nearest point of the circle at the centre's altitude, facing the centre;
* on the circle the velocity is the tangential speed plus (radius - distance) towards the circle, and the heading
  follows the yaw behaviour: 0 facing the centre, 1 the heading the command found, 2 uncontrolled (held here),
  3 along the tangent, 4 the pilot's (held here: no sticks).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from sitl_bridge.dynamics import velocity_toward
from sitl_bridge.multirotor import MultirotorParams, VehicleState, VelocityCommand

RADIUS_MIN_M = 1.0
VELOCITY_MAX_MPS = 10.0
ACCELERATION_MAX_MPS2 = 2.0
ON_CIRCLE_M = 1.0  # FlightTaskOrbit's _horizontal_acceptance_radius
ALTITUDE_ACCEPTANCE_M = 0.8  # PX4's NAV_MC_ALT_RAD default
YAW_TO_CENTER, YAW_INITIAL, YAW_UNCONTROLLED, YAW_TANGENT, YAW_PILOT = range(5)


@dataclass
class Orbit:
    """One orbit: its centre (local NED, m), radius (m), signed tangential speed (m/s; > 0 clockwise) and yaw
    behaviour."""

    north_m: float
    east_m: float
    down_m: float
    radius_m: float = RADIUS_MIN_M
    velocity_mps: float = 1.0
    yaw_behaviour: int = YAW_TO_CENTER
    initial_yaw_rad: float = 0.0

    def apply(self, radius: float, speed: float, yaw_behaviour: float, centre: tuple[float, float] | None,
              down_m: float | None, yaw_rad: float, radius_max_m: float) -> bool:
        """A DO_ORBIT's parameters (NaN: keep); False when the radius is out of range (then the radius and speed
        stay as they were and the rest is taken, as in PX4)."""
        clockwise = self.velocity_mps > 0.0
        new_radius, new_speed = self.radius_m, abs(self.velocity_mps)
        if math.isfinite(radius):
            clockwise, new_radius = radius > 0.0, abs(radius)
        if math.isfinite(speed):
            new_speed = speed
        accepted = RADIUS_MIN_M <= new_radius <= radius_max_m
        if accepted:
            self.radius_m, self.velocity_mps = sanitized(new_radius, new_speed if clockwise else -new_speed,
                                                         radius_max_m)
        if math.isfinite(yaw_behaviour):
            self.yaw_behaviour = int(yaw_behaviour)
        self.initial_yaw_rad = yaw_rad
        if centre is not None:
            self.north_m, self.east_m = centre
        if down_m is not None:
            self.down_m = down_m
        return accepted

    def on_circle(self, state: VehicleState) -> bool:
        distance = math.hypot(state.north_m - self.north_m, state.east_m - self.east_m)
        return (abs(distance - self.radius_m) < ON_CIRCLE_M
                and abs(state.down_m - self.down_m) < ALTITUDE_ACCEPTANCE_M)

    def command(self, state: VehicleState, airframe: MultirotorParams, cruise_mps: float) -> VelocityCommand:
        """This tick's velocity command: the approach to the circle, or the orbit itself."""
        dn, de = state.north_m - self.north_m, state.east_m - self.east_m  # centre to the vehicle
        distance = math.hypot(dn, de)
        to_centre_yaw = math.atan2(-de, -dn) if distance > 0.0 else state.yaw_rad
        if not self.on_circle(state):  # the nearest point of the circle, at the centre's altitude
            scale = self.radius_m / distance if distance > 0.0 else 0.0
            target_n = self.north_m + dn * scale if distance > 0.0 else self.north_m + self.radius_m
            target_e = self.east_m + de * scale
            approach = velocity_toward(state, target_n, target_e, self.down_m, airframe, speed_xy_mps=cruise_mps)
            return VelocityCommand(approach.north_mps, approach.east_mps, approach.down_mps, to_centre_yaw)
        un, ue = dn / distance, de / distance
        # PX4 feeds the centripetal acceleration forward (v² / r towards the centre); this vehicle follows velocity
        # commands through a first-order lag, which on a circle turning at w costs a phase of atan(w tau) and a
        # gain of 1 / sqrt(1 + (w tau)²): the command leads and is scaled by as much, or the vehicle drifts
        # outwards and slows down.
        w_tau = self.velocity_mps / self.radius_m * airframe.velocity_time_constant_s
        lead, speed = math.atan(w_tau), self.velocity_mps * math.sqrt(1.0 + w_tau * w_tau)
        tn, te = -ue * math.cos(lead) - un * math.sin(lead), un * math.cos(lead) - ue * math.sin(lead)
        radial = self.radius_m - distance
        north = tn * speed + radial * un  # (-e, n) turns north towards east: clockwise
        east = te * speed + radial * ue
        hold = velocity_toward(state, state.north_m, state.east_m, self.down_m, airframe, speed_xy_mps=0.0)
        yaw = {YAW_TO_CENTER: to_centre_yaw, YAW_INITIAL: self.initial_yaw_rad,
               YAW_TANGENT: math.atan2(math.copysign(1.0, self.velocity_mps) * dn,
                                       -math.copysign(1.0, self.velocity_mps) * de)}.get(self.yaw_behaviour)
        return VelocityCommand(north, east, hold.down_mps, yaw)


def sanitized(radius_m: float, velocity_mps: float, radius_max_m: float) -> tuple[float, float]:
    """FlightTaskOrbit::_sanitizeParams: the radius within range, the speed within 10 m/s and within what the
    centripetal acceleration limit allows at that radius (the speed gives way, not the radius)."""
    radius_m = min(max(radius_m, RADIUS_MIN_M), radius_max_m)
    velocity_mps = min(max(velocity_mps, -VELOCITY_MAX_MPS), VELOCITY_MAX_MPS)
    if velocity_mps * velocity_mps >= ACCELERATION_MAX_MPS2 * radius_m:
        velocity_mps = math.copysign(math.sqrt(ACCELERATION_MAX_MPS2 * radius_m), velocity_mps)
    return radius_m, velocity_mps
