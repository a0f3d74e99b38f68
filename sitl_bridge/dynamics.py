"""Multirotor dynamics: a 3-D point mass behind a velocity controller, with wind, battery and ground.

Everything here is a pure function over frozen dataclasses: no I/O, no global randomness. The SITL calls
:func:`step` (one vehicle, floats, with ground contact) at 100-250 Hz; the training environment calls
:func:`step_batch` (N airborne vehicles, numpy arrays). Both run the same airborne physics code; what
:func:`step` adds to it:

* Ground (:func:`step` only): flat at ``down = 0``. On the ground (armed, no climb command) the vehicle
  rests: no motion, no yawing. A climb command lifts off from rest. While armed, touching the ground
  ends the flight for the rest of the step (or lifts off again at once if the command climbs).
* Disarmed (:func:`step` only): motors off. On the ground nothing but time moves; in the air the vehicle
  falls ballistically (no drag, horizontal velocity kept, gusts still drift it) until it hits the ground.

The pieces: the parameters, state and command (``sitl_bridge/multirotor.py``), the wind
(``sitl_bridge/wind.py``) and the airborne physics both entry points share (``sitl_bridge/airborne.py``).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sitl_bridge.airborne import (
    airborne_power_w,
    battery_after,
    clamp_velocity,
    clamp_yaw_rate,
    fly_airborne,
    may_touch_down,
    touchdown_time,
    turn_at,
    turn_toward,
)
from sitl_bridge.multirotor import GRAVITY_MPS2, HOVER, MultirotorParams, VehicleState, VelocityCommand
from sitl_bridge.scalar_math import wrap_angle
from sitl_bridge.wind import Wind, gust_drift

__all__ = ["HOVER", "BatchState", "MultirotorParams", "VehicleState", "VelocityCommand", "Wind", "attitude",
           "clamp_command", "ground_velocity", "power_w", "step", "step_batch", "velocity_toward"]
"""The model's public names, for the packages that use the model as a whole (``policies/env/core.py`` reaches
them as ``dynamics.X``); the parameters, state, command and wind are defined in the modules named above."""


# One vehicle, with ground contact and disarming (the SITL) ----------------------------------------
def _clamped(cmd: VelocityCommand, params: MultirotorParams) -> tuple:
    """The command's limited values as a plain tuple (north, east, down, yaw, yaw_rate).

    Non-finite numbers (NaN, inf) become 0 for velocities and yaw rate and ``None`` (hold heading)
    for an absolute yaw: a garbage setpoint should stop the vehicle, not point it anywhere.
    """
    n, e, d = clamp_velocity(cmd.north_mps, cmd.east_mps, cmd.down_mps, params)
    yaw, rate = cmd.yaw_rad, cmd.yaw_rate_rad_s
    if yaw is not None:
        yaw = wrap_angle(yaw) if math.isfinite(yaw) else None
    if rate is not None:
        rate = clamp_yaw_rate(rate, params)
    return n, e, d, yaw, rate


def clamp_command(cmd: VelocityCommand, params: MultirotorParams) -> VelocityCommand:
    """The command :func:`step` actually flies: speed, climb/descent and yaw-rate limits applied."""
    return VelocityCommand(*_clamped(cmd, params))


def power_w(state: VehicleState, cmd: VelocityCommand, params: MultirotorParams, wind: Wind,
            armed: bool = True) -> float:
    """Electrical power (W) :func:`step` draws from ``state`` with ``cmd`` held (until any touchdown).

    Depends only on the command, the steady wind and whether the vehicle flies, so it is constant over
    a step and the battery drain is exact. Gusts are ignored: their mean effect is small.
    """
    if not armed:
        return 0.0
    cn, ce, cd, _, _ = _clamped(cmd, params)
    if state.on_ground and not cd < 0.0:
        return params.idle_power_w
    return airborne_power_w(cn, ce, cd, params, wind)


def _fly(n: float, e: float, d: float, vn: float, ve: float, vd: float, cn: float, ce: float, cd: float,
         t0: float, duration: float, params: MultirotorParams, wind: Wind) -> tuple:
    """Armed flight for up to ``duration`` s from time ``t0``: the shared airborne physics, cut short
    (and stopped: no sliding) at touchdown. Returns (time flown, n, e, d, vn, ve, vd, an, ae, ad, landed).
    """
    touchdown = None
    if may_touch_down(d, vd, cd, duration):
        touchdown = touchdown_time(d, vd, cd, params.max_accel_z_mps2, params.velocity_time_constant_s,
                                    duration)
    if touchdown is None:
        n, e, d, vn, ve, vd, an, ae, ad = fly_airborne(n, e, d, vn, ve, vd, cn, ce, cd, t0, duration, params, wind)
        return duration, n, e, min(d, 0.0), vn, ve, vd, an, ae, ad, False
    n, e, *_ = fly_airborne(n, e, d, vn, ve, vd, cn, ce, cd, t0, touchdown, params, wind)
    return touchdown, n, e, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, True


def _fall(state: VehicleState, params: MultirotorParams, wind: Wind, dt_s: float) -> VehicleState:
    """Disarmed in the air: ballistic fall (no drag) until the ground, then rest."""
    d0, vd0 = min(state.down_m, 0.0), state.vd_mps
    # Positive root of d0 + vd0*s + g/2*s^2 = 0, in whichever form avoids cancellation.
    root = math.sqrt(vd0 * vd0 - 2.0 * GRAVITY_MPS2 * d0)
    if vd0 < 0.0:
        t_hit = (root - vd0) / GRAVITY_MPS2
    else:
        t_hit = -2.0 * d0 / (vd0 + root) if root > 0.0 else 0.0
    flown = min(dt_s, t_hit)
    gn, ge = gust_drift(params, wind, state.time_s, state.time_s + flown)
    n1, e1 = state.north_m + state.vn_mps * flown + gn, state.east_m + state.ve_mps * flown + ge
    t1 = state.time_s + dt_s
    if t_hit <= dt_s:
        return VehicleState(t1, n1, e1, 0.0, 0.0, 0.0, 0.0, state.yaw_rad, 0.0, 0.0, 0.0, state.battery_wh,
                            True)
    d1 = min(0.0, d0 + vd0 * flown + 0.5 * GRAVITY_MPS2 * flown * flown)
    return VehicleState(t1, n1, e1, d1, state.vn_mps, state.ve_mps, vd0 + GRAVITY_MPS2 * flown, state.yaw_rad,
                        0.0, 0.0, GRAVITY_MPS2, state.battery_wh, False)


def step(state: VehicleState, cmd: VelocityCommand, params: MultirotorParams, wind: Wind, dt_s: float,
         armed: bool = True) -> VehicleState:
    """Advance the vehicle by ``dt_s`` seconds with ``cmd`` held constant; exact for any ``dt_s``."""
    if not 0.0 <= dt_s < math.inf:
        raise ValueError(f"dt_s must be finite and >= 0, got {dt_s}")
    t0 = state.time_s
    if not armed:
        if state.on_ground:
            return VehicleState(t0 + dt_s, state.north_m, state.east_m, 0.0, 0.0, 0.0, 0.0, state.yaw_rad,
                                0.0, 0.0, 0.0, state.battery_wh, True)
        return _fall(state, params, wind, dt_s)

    cn, ce, cd, yaw_target, yaw_rate = _clamped(cmd, params)
    climbing = cd < 0.0
    if state.on_ground:
        if not climbing:  # rest: only time and the idle drain move
            battery = battery_after(state.battery_wh, params.idle_power_w, dt_s)
            return VehicleState(t0 + dt_s, state.north_m, state.east_m, 0.0, 0.0, 0.0, 0.0, state.yaw_rad,
                                0.0, 0.0, 0.0, battery, True)
        # Lift off from rest.
        flight = _fly(state.north_m, state.east_m, 0.0, 0.0, 0.0, 0.0, cn, ce, cd, t0, dt_s, params, wind)
    else:
        flight = _fly(state.north_m, state.east_m, min(state.down_m, 0.0), state.vn_mps, state.ve_mps,
                      state.vd_mps, cn, ce, cd, t0, dt_s, params, wind)
    airborne_s, n, e, d, vn, ve, vd, an, ae, ad, landed = flight
    if landed and climbing and airborne_s < dt_s:
        # Touched down while still commanded to climb (e.g. braking a descent too close to the
        # ground): lift off again at once, exactly as the next step would.
        flight = _fly(n, e, 0.0, 0.0, 0.0, 0.0, cn, ce, cd, t0 + airborne_s, dt_s - airborne_s, params, wind)
        _, n, e, d, vn, ve, vd, an, ae, ad, landed = flight
        airborne_s = dt_s
    battery = battery_after(state.battery_wh, airborne_power_w(cn, ce, cd, params, wind), airborne_s)
    if airborne_s < dt_s:  # resting on the ground for the rest of the step
        battery = battery_after(battery, params.idle_power_w, dt_s - airborne_s)
    yaw = state.yaw_rad  # no yaw command (and no yawing on the ground): hold
    if yaw_target is not None:
        yaw = turn_toward(yaw, yaw_target, params.max_yaw_rate_rad_s, airborne_s)
    elif yaw_rate is not None:
        yaw = turn_at(yaw, yaw_rate, airborne_s)
    return VehicleState(t0 + dt_s, n, e, d, vn, ve, vd, yaw, an, ae, ad, battery, landed)


# N airborne vehicles at once (the training environment) ------------------------------------------
_BATCH_FIELDS = ("north_m", "east_m", "down_m", "vn_mps", "ve_mps", "vd_mps", "yaw_rad", "battery_wh")


@dataclass(slots=True)
class BatchState:
    """N airborne vehicles: float64 arrays of shape (N,), fields as in :class:`VehicleState`. The caller
    keeps the time (see :func:`step_batch`); accelerations (used only by :func:`attitude`) are not kept."""

    north_m: np.ndarray
    east_m: np.ndarray
    down_m: np.ndarray
    vn_mps: np.ndarray
    ve_mps: np.ndarray
    vd_mps: np.ndarray
    yaw_rad: np.ndarray
    battery_wh: np.ndarray

    @classmethod
    def from_states(cls, states: Sequence[VehicleState]) -> BatchState:
        """Stack airborne scalar states (``on_ground`` ones are rejected: the batch has no ground)."""
        grounded = [i for i, s in enumerate(states) if s.on_ground]
        if grounded:
            raise ValueError(f"BatchState.from_states: states {grounded[:5]} are on the ground")
        return cls(*(np.array([getattr(s, name) for s in states], dtype=np.float64) for name in _BATCH_FIELDS))

    def state(self, i: int, time_s: float = 0.0) -> VehicleState:
        """Vehicle ``i`` as a :class:`VehicleState` at ``time_s``: airborne, accelerations 0."""
        n, e, d, vn, ve, vd, yaw, battery = (float(getattr(self, name)[i]) for name in _BATCH_FIELDS)
        return VehicleState(time_s, n, e, d, vn, ve, vd, yaw, 0.0, 0.0, 0.0, battery, on_ground=False)

    def set(self, i: int, state: VehicleState) -> None:
        """Overwrite vehicle ``i`` with an airborne scalar state (an environment reset)."""
        if state.on_ground:
            raise ValueError("BatchState.set: the state is on the ground")
        for name in _BATCH_FIELDS:
            getattr(self, name)[i] = getattr(state, name)

    def copy(self) -> BatchState:
        """An independent copy (new arrays)."""
        return BatchState(*(getattr(self, name).copy() for name in _BATCH_FIELDS))


def step_batch(state: BatchState, cmd_north, cmd_east, cmd_down, params: MultirotorParams, wind: Wind,
               t0_s: float | np.ndarray, dt_s: float, out: BatchState | None = None, *,
               cmd_yaw_rad=None, cmd_yaw_rate_rad_s=None) -> BatchState:
    """Advance N AIRBORNE vehicles by ``dt_s`` with their velocity commands (NED, m/s, arrays or floats)
    held: the same physics, to rounding, as ``step(state.state(i, t0_s[i]), VelocityCommand(...))`` each.

    ``t0_s`` is each vehicle's absolute time at the start (a float or an (N,) array; it sets the gust
    phase; the caller advances it). Heading is held unless ``cmd_yaw_rate_rad_s`` and/or ``cmd_yaw_rad``
    are given, with :class:`VelocityCommand`'s rules (a finite heading target wins over the rate).
    Ground contact is NOT modelled: callers must keep the vehicles airborne; a ValueError is raised if
    any vehicle would touch the ground during the step (a vectorised bound, confirmed per flagged vehicle
    by the touchdown search :func:`step` uses). Results go to ``out`` (may be ``state``) or new arrays.
    """
    if not 0.0 <= dt_s < math.inf:
        raise ValueError(f"dt_s must be finite and >= 0, got {dt_s}")
    if state.north_m.shape == (1,):  # one vehicle (the single environment): numpy's per-call overhead
        return _step_one(state, cmd_north, cmd_east, cmd_down, params, wind, t0_s, dt_s, out,  # would dominate
                         cmd_yaw_rad, cmd_yaw_rate_rad_s)
    s, xp = state, np
    cn, ce, cd = clamp_velocity(np.asarray(cmd_north, np.float64), np.asarray(cmd_east, np.float64),
                                 np.asarray(cmd_down, np.float64), params, xp)
    cd = np.broadcast_to(cd, s.down_m.shape)
    for i in np.flatnonzero(may_touch_down(s.down_m, s.vd_mps, cd, dt_s, xp)):
        if s.down_m[i] > 0.0 or touchdown_time(float(s.down_m[i]), float(s.vd_mps[i]), float(cd[i]),
                                                params.max_accel_z_mps2, params.velocity_time_constant_s,
                                                dt_s) is not None:
            raise ValueError(f"step_batch: vehicle {i} (down_m={s.down_m[i]:.3f}, vd_mps={s.vd_mps[i]:.3f}) "
                             f"would touch the ground; step_batch models airborne flight only")
    n, e, d, vn, ve, vd, _, _, _ = fly_airborne(s.north_m, s.east_m, s.down_m, s.vn_mps, s.ve_mps, s.vd_mps,
                                             cn, ce, cd, t0_s, dt_s, params, wind, xp)
    battery = battery_after(s.battery_wh, airborne_power_w(cn, ce, cd, params, wind, xp), dt_s, xp)
    yaw = s.yaw_rad
    if cmd_yaw_rate_rad_s is not None:
        yaw = turn_at(yaw, clamp_yaw_rate(np.asarray(cmd_yaw_rate_rad_s, np.float64), params, xp), dt_s, xp)
    if cmd_yaw_rad is not None:  # where a target is given it wins over the rate, as in step()
        target = np.asarray(cmd_yaw_rad, np.float64)
        has_target = np.isfinite(target)
        target = wrap_angle(np.where(has_target, target, 0.0), xp)
        yaw = np.where(has_target, turn_toward(s.yaw_rad, target, params.max_yaw_rate_rad_s, dt_s, xp), yaw)
    if out is None:
        out = BatchState(*(np.empty(s.north_m.shape) for _ in _BATCH_FIELDS))
    for name, value in zip(_BATCH_FIELDS, (n, e, d, vn, ve, vd, yaw, battery)):
        getattr(out, name)[...] = value
    return out


def _step_one(state: BatchState, cmd_north, cmd_east, cmd_down, params: MultirotorParams, wind: Wind, t0_s,
              dt_s: float, out: BatchState | None, cmd_yaw_rad, cmd_yaw_rate_rad_s) -> BatchState:
    """:func:`step_batch` for N = 1 through the scalar backend (the same shared physics, via :func:`step`)."""
    def first(value):
        if value is None:
            return None
        return float(value[0]) if isinstance(value, np.ndarray) and value.ndim else float(value)

    yaw = first(cmd_yaw_rad)
    command = VelocityCommand(first(cmd_north), first(cmd_east), first(cmd_down),
                              yaw if yaw is not None and math.isfinite(yaw) else None, first(cmd_yaw_rate_rad_s))
    s = state
    before = VehicleState(first(t0_s), s.north_m.item(), s.east_m.item(), s.down_m.item(), s.vn_mps.item(),
                          s.ve_mps.item(), s.vd_mps.item(), s.yaw_rad.item(), 0.0, 0.0, 0.0, s.battery_wh.item(),
                          on_ground=False)
    after = step(before, command, params, wind, dt_s)
    if after.on_ground or before.down_m > 0.0:
        raise ValueError(f"step_batch: vehicle 0 (down_m={before.down_m:.3f}, vd_mps={before.vd_mps:.3f}) "
                         f"would touch the ground; step_batch models airborne flight only")
    if out is None:
        out = BatchState(*(np.empty(1) for _ in _BATCH_FIELDS))
    out.north_m[0], out.east_m[0], out.down_m[0] = after.north_m, after.east_m, after.down_m
    out.vn_mps[0], out.ve_mps[0], out.vd_mps[0] = after.vn_mps, after.ve_mps, after.vd_mps
    out.yaw_rad[0], out.battery_wh[0] = after.yaw_rad, after.battery_wh
    return out


def ground_velocity(state: VehicleState, params: MultirotorParams, wind: Wind) -> tuple[float, float, float]:
    """Velocity over ground (NED, m/s): the controller's velocity plus the leaked horizontal gust."""
    if state.on_ground:
        return 0.0, 0.0, 0.0
    gn, ge, _ = wind.gust_velocity(state.time_s)
    r = params.gust_response
    return state.vn_mps + r * gn, state.ve_mps + r * ge, state.vd_mps


def attitude(state: VehicleState, params: MultirotorParams, wind: Wind) -> tuple[float, float, float]:
    """Roll, pitch, yaw (rad) that produce the current acceleration while holding against the air.

    The thrust must supply the acceleration plus cancel drag ``-k |v_air| v_air``; its direction, turned
    into the yaw frame, gives the tilt. Forward acceleration pitches the nose down (negative pitch),
    rightward acceleration rolls right (positive roll). Level on the ground.
    """
    if state.on_ground:
        return 0.0, 0.0, state.yaw_rad
    gn, ge, _ = wind.gust_velocity(state.time_s)
    r = params.gust_response
    # Air-relative velocity = ground velocity - air velocity (steady wind + gust).
    van = state.vn_mps + r * gn - (wind.north_mps + gn)
    vae = state.ve_mps + r * ge - (wind.east_mps + ge)
    k = params.drag_tilt_per_mps2 * math.hypot(van, vae)
    fn, fe = state.an_mps2 + k * van, state.ae_mps2 + k * vae
    lift = max(GRAVITY_MPS2 - state.ad_mps2, 0.1 * GRAVITY_MPS2)  # floor: tilt stays meaningful in a fall
    cos_y, sin_y = math.cos(state.yaw_rad), math.sin(state.yaw_rad)
    forward, right = cos_y * fn + sin_y * fe, -sin_y * fn + cos_y * fe
    pitch = math.atan2(-forward, lift)
    roll = math.atan2(right, math.hypot(forward, lift))
    return roll, pitch, state.yaw_rad


def velocity_toward(state: VehicleState, target_n: float, target_e: float, target_d: float,
                    params: MultirotorParams, speed_xy_mps: float, speed_z_mps: float | None = None,
                    gain_per_s: float = 1.0) -> VelocityCommand:
    """Position controller: a velocity command toward a point (NED, m), speed-limited.

    Proportional on distance (``gain_per_s``), capped by the requested and physical speeds and by the
    speed from which the vehicle can still brake at half its acceleration limit (so long legs do not
    overshoot). ``speed_z_mps`` defaults to the climb/descent limits. Heading is held.
    """
    # Aim from where the vehicle will be once its velocity lag has played out (p + tau * v): this lead
    # turns the underdamped P + lag loop (about 5 % overshoot at gain 1/s) into an overdamped one.
    lead = params.velocity_time_constant_s
    dn = target_n - state.north_m - lead * state.vn_mps
    de = target_e - state.east_m - lead * state.ve_mps
    dd = target_d - state.down_m - lead * state.vd_mps
    dist_xy = math.hypot(dn, de)
    vn = ve = vd = 0.0
    if dist_xy > 0.0:
        speed = min(speed_xy_mps, params.max_speed_xy_mps, gain_per_s * dist_xy,
                    math.sqrt(params.max_accel_xy_mps2 * dist_xy))
        vn, ve = dn / dist_xy * speed, de / dist_xy * speed
    if dd != 0.0:
        limit = params.max_speed_down_mps if dd > 0.0 else params.max_speed_up_mps
        if speed_z_mps is not None:
            limit = min(limit, speed_z_mps)
        speed = min(limit, gain_per_s * abs(dd), math.sqrt(params.max_accel_z_mps2 * abs(dd)))
        vd = math.copysign(speed, dd)
    return VelocityCommand(vn, ve, vd)
