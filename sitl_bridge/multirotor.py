"""The simulated multirotor's parameters, state and velocity command: frozen dataclasses that the dynamics
(``sitl_bridge/dynamics.py``) step, units in the field names, NED frame relative to home."""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

from missions.validation import NON_NEGATIVE, POSITIVE, Interval, check_fields

GRAVITY_MPS2 = 9.80665


@dataclass(frozen=True, slots=True)
class MultirotorParams:
    """Physical limits and constants of the simulated multirotor (units in the field names)."""

    velocity_time_constant_s: float = 0.5  # first-order lag of velocity tracking, s
    max_speed_xy_mps: float = 12.0  # horizontal speed limit, m/s
    max_speed_up_mps: float = 3.0  # climb rate limit, m/s
    max_speed_down_mps: float = 1.5  # descent rate limit, m/s
    max_accel_xy_mps2: float = 5.0  # horizontal acceleration limit, m/s^2
    max_accel_z_mps2: float = 4.0  # vertical acceleration limit, m/s^2
    max_yaw_rate_rad_s: float = math.radians(60.0)  # yaw rate limit, rad/s
    gust_response: float = 0.3  # fraction of the horizontal gust velocity the controller fails to reject
    drag_tilt_per_mps2: float = 0.03  # drag decel. per (m/s)^2 of airspeed, 1/m: tan(tilt) = k*|v_air|^2/g
    battery_capacity_wh: float = 90.0  # usable energy of a full battery, Wh
    hover_power_w: float = 280.0  # electrical power to hover in still air, W
    power_per_airspeed2_w: float = 1.0  # extra power per (m/s)^2 of commanded horizontal airspeed, W
    climb_power_w_per_mps: float = 40.0  # extra power per m/s of commanded climb rate, W
    idle_power_w: float = 10.0  # armed, resting on the ground, W

    def __post_init__(self) -> None:
        # Limits, time constants, capacity and hover power must be > 0; the rest may be 0 (no effect).
        may_be_zero = {"drag_tilt_per_mps2": NON_NEGATIVE, "power_per_airspeed2_w": NON_NEGATIVE,
                       "climb_power_w_per_mps": NON_NEGATIVE, "idle_power_w": NON_NEGATIVE,
                       "gust_response": Interval(0.0, 1.0)}
        check_fields(self, ((f.name, may_be_zero.get(f.name, POSITIVE)) for f in fields(self)))


@dataclass(frozen=True, slots=True)
class VehicleState:
    """Full state of the simulated vehicle (NED, relative to home; the ground is at ``down_m = 0``).

    ``vn/ve/vd`` is the velocity the controller holds; :func:`ground_velocity` adds the gust part.
    ``an/ae/ad`` is the controller's acceleration at ``time_s`` (with the last command), used for
    attitude; it is instantaneous rather than a step mean so that the state does not depend on how
    time was split into steps.
    """

    time_s: float = 0.0
    north_m: float = 0.0
    east_m: float = 0.0
    down_m: float = 0.0  # <= 0 always
    vn_mps: float = 0.0
    ve_mps: float = 0.0
    vd_mps: float = 0.0
    yaw_rad: float = 0.0  # heading, wrapped to (-pi, pi]
    an_mps2: float = 0.0
    ae_mps2: float = 0.0
    ad_mps2: float = 0.0
    battery_wh: float = 90.0  # energy left
    on_ground: bool = True


@dataclass(frozen=True, slots=True)
class VelocityCommand:
    """Velocity setpoint (NED, m/s) with an optional heading or yaw-rate target."""

    north_mps: float = 0.0
    east_mps: float = 0.0
    down_mps: float = 0.0
    yaw_rad: float | None = None  # absolute heading to turn to (at max yaw rate, shortest way)
    yaw_rate_rad_s: float | None = None  # used when yaw_rad is None; both None = hold heading


HOVER = VelocityCommand()
