"""Multirotor dynamics: a 3-D point mass behind a velocity controller, with wind, battery and ground.

Everything here is a pure function over frozen dataclasses: no I/O, no global randomness. The SITL calls
:func:`step` (one vehicle, floats, with ground contact) at 100-250 Hz; the training environment calls
:func:`step_batch` (N airborne vehicles, numpy arrays). Both run the same airborne physics code.

The model, per axis group (horizontal = 2-D vector, vertical = 1-D):

* The controller's velocity ``v`` tracks the (clamped) command ``c`` as a first-order lag with time
  constant ``tau``, i.e. ``dv/dt = (c - v) / tau``, except that ``|dv/dt|`` is capped at ``a_max``.
  With ``c`` constant the error ``e = c - v`` keeps its direction and its magnitude follows
  phase 1 (``|e| > a_max * tau``): linear decrease at ``a_max``; phase 2: ``|e| = |e0| exp(-t / tau)``.
  Both phases have closed-form position integrals, so a step is EXACT for any step size: one
  1 s step equals 100 steps of 10 ms to rounding error. Every other ingredient is chosen to keep that
  property (gusts are a function of absolute time, power is constant while the command is, touchdown
  is found by a root find on the closed-form trajectory, the stored acceleration is instantaneous).
* Wind: the velocity controller fully rejects the steady wind (it holds ground velocity) and a
  fraction ``gust_response`` of the horizontal gusts leaks through as ground velocity. The altitude
  loop is modelled as rejecting vertical gusts entirely (a multirotor's thrust acts directly on that
  axis), which also means a gust can never push a vehicle through the ground.
* Ground (:func:`step` only): flat at ``down = 0``. On the ground (armed, no climb command) the vehicle
  rests: no motion, no yawing. A climb command lifts off from rest. While armed, touching the ground
  ends the flight for the rest of the step (or lifts off again at once if the command climbs).
* Disarmed (:func:`step` only): motors off. On the ground nothing but time moves; in the air the vehicle
  falls ballistically (no drag, horizontal velocity kept, gusts still drift it) until it hits the ground.

The backend trick: the airborne physics (section "Shared airborne physics") is written once, with no
Python ``if`` on values: only arithmetic, ``abs`` and ``xp.where/minimum/maximum/clip/isfinite/hypot/
copysign/expm1/cos/fmod``. With ``xp=numpy`` it steps arrays of N vehicles (:func:`step_batch`); with
``xp=_Scalar`` (the same names for Python floats) one vehicle, nearly as fast as plain scalar code.
"""
from __future__ import annotations

import math
import random
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

GRAVITY_MPS2 = 9.80665
GUSTS_PER_AXIS = 3
GUST_PERIOD_RANGE_S = (3.0, 30.0)
VERTICAL_GUST_FRACTION = 0.3  # vertical gusts are this fraction of the horizontal ones
_PI, _TWO_PI = math.pi, 2.0 * math.pi


class _Scalar:
    """numpy's names for the functions the shared physics uses, for Python floats: ``math`` and conditional
    expressions (faster than numpy or min/max on one float). As with numpy, all arguments are evaluated."""

    isfinite, hypot, copysign = math.isfinite, math.hypot, math.copysign
    expm1, cos, fmod = math.expm1, math.cos, math.fmod
    where = staticmethod(lambda condition, if_true, if_false: if_true if condition else if_false)
    minimum = staticmethod(lambda a, b: a if a < b else b)
    maximum = staticmethod(lambda a, b: a if a > b else b)
    clip = staticmethod(lambda x, lo, hi: lo if x < lo else hi if x > hi else x)


def _wrap(angle_rad, xp=_Scalar):
    """Wrap an angle to (-pi, pi], exactly (fmod is exact, and so is the one +-2pi correction)."""
    r = xp.fmod(angle_rad, _TWO_PI)  # in (-2pi, 2pi)
    return xp.where(r > _PI, r - _TWO_PI, xp.where(r <= -_PI, r + _TWO_PI, r))


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
        non_negative = {"gust_response", "drag_tilt_per_mps2", "power_per_airspeed2_w",
                        "climb_power_w_per_mps", "idle_power_w"}
        for name in self.__dataclass_fields__:
            value = getattr(self, name)
            if name == "gust_response":
                if not 0.0 <= value <= 1.0:
                    raise ValueError(f"MultirotorParams.{name} must be in [0, 1], got {value}")
            elif name in non_negative:
                if not 0.0 <= value < math.inf:
                    raise ValueError(f"MultirotorParams.{name} must be finite and >= 0, got {value}")
            elif not 0.0 < value < math.inf:
                raise ValueError(f"MultirotorParams.{name} must be finite and > 0, got {value}")


@dataclass(frozen=True, slots=True)
class Wind:
    """Steady wind (NED velocity of the air, m/s) plus deterministic gusts.

    Gusts are, per axis, a sum of :data:`GUSTS_PER_AXIS` sinusoids whose periods (3-30 s), phases and
    relative weights are drawn once from ``random.Random(seed)``. The horizontal RMS gust speed is
    ``gust_mps``; vertical gusts are :data:`VERTICAL_GUST_FRACTION` of that. Being a function of absolute
    time is what lets :meth:`gust_displacement` integrate them exactly for any step.
    """

    north_mps: float = 0.0
    east_mps: float = 0.0
    gust_mps: float = 0.0  # horizontal RMS gust speed, m/s; 0 = no gusts
    seed: int = 0  # picks the gust periods, phases and weights
    # Per axis (north, east, down): tuple of (amplitude m/s, angular frequency rad/s, phase rad,
    # amplitude / angular frequency m), the last one precomputed for the displacement integral.
    _terms: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("north_mps", "east_mps"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"Wind.{name} must be finite, got {getattr(self, name)}")
        if not 0.0 <= self.gust_mps < math.inf:
            raise ValueError(f"Wind.gust_mps must be finite and >= 0, got {self.gust_mps}")
        rng = random.Random(self.seed)
        log_lo, log_hi = (math.log(p) for p in GUST_PERIOD_RANGE_S)
        terms = []
        for axis_scale in (1.0, 1.0, VERTICAL_GUST_FRACTION):
            periods = [math.exp(rng.uniform(log_lo, log_hi)) for _ in range(GUSTS_PER_AXIS)]
            weights = [rng.uniform(0.5, 1.0) for _ in range(GUSTS_PER_AXIS)]
            phases = [rng.uniform(0.0, _TWO_PI) for _ in range(GUSTS_PER_AXIS)]
            # RMS of a sinusoid sum is sqrt(sum(A^2) / 2) per axis; sum(A^2) = gust^2 makes the
            # horizontal (two-axis) RMS speed equal gust_mps.
            norm = self.gust_mps * axis_scale / math.sqrt(sum(w * w for w in weights))
            terms.append(tuple((w * norm, _TWO_PI / p, ph, w * norm * p / _TWO_PI)
                               for w, p, ph in zip(weights, periods, phases)))
        object.__setattr__(self, "_terms", tuple(terms))

    def gust_velocity(self, time_s: float) -> tuple[float, float, float]:
        """Gust part of the air velocity (NED, m/s) at absolute simulated time ``time_s``."""
        return tuple(sum(a * math.sin(w * time_s + ph) for a, w, ph, _ in axis)  # type: ignore[return-value]
                     for axis in self._terms)

    def gust_displacement(self, t0_s: float, t1_s: float) -> tuple[float, float, float]:
        """Exact integral of :meth:`gust_velocity` from ``t0_s`` to ``t1_s`` (NED, m)."""
        return tuple(_axis_displacement(axis, t0_s, t1_s) for axis in self._terms)  # type: ignore[return-value]


def _axis_displacement(terms: tuple, t0_s, t1_s, xp=_Scalar):
    """Integral over [t0, t1] of sum(a * sin(w t + ph)) = sum(a / w * (cos(w t0 + ph) - cos(w t1 + ph)))."""
    total = 0.0
    for _, w, ph, a_over_w in terms:  # the few sinusoids of one axis (a loop over terms, not vehicles)
        total = total + a_over_w * (xp.cos(w * t0_s + ph) - xp.cos(w * t1_s + ph))
    return total


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


# Shared airborne physics (backend-generic: xp = _Scalar or numpy) -----------------------------------
def _clamp_velocity(n, e, d, params: MultirotorParams, xp=_Scalar):
    """Commanded velocity with non-finite parts zeroed (garbage stops the vehicle), the horizontal
    speed limited keeping the direction, and the climb/descent rates limited."""
    finite, where = xp.isfinite, xp.where
    n, e, d = where(finite(n), n, 0.0), where(finite(e), e, 0.0), where(finite(d), d, 0.0)
    limit = params.max_speed_xy_mps
    scale = limit / xp.maximum(xp.hypot(n, e), limit)  # exactly 1 within the limit
    return n * scale, e * scale, xp.clip(d, -params.max_speed_up_mps, params.max_speed_down_mps)


def _clamp_yaw_rate(rate, params: MultirotorParams, xp=_Scalar):
    """Yaw-rate command limited to the max yaw rate; non-finite becomes 0 (hold)."""
    limit = params.max_yaw_rate_rad_s
    return xp.where(xp.isfinite(rate), xp.clip(rate, -limit, limit), 0.0)


def _track(e0, a_max: float, tau: float, t, xp=_Scalar):
    """Velocity-error magnitude after ``t`` s, and its integral over [0, t], starting from ``e0 >= 0``.

    Phase 1 (error above ``a_max * tau``, where the first-order law would ask for more than ``a_max``)
    lasts ``t_lin``, clipped to [0, t]; the exponential phase 2 takes the rest (possibly 0 s).
    """
    t_lin = xp.clip((e0 - a_max * tau) / a_max, 0.0, t)
    e_mid = e0 - a_max * t_lin  # error when phase 1 ends (or at t)
    shrink = xp.expm1((t_lin - t) / tau)  # exp(-t2/tau) - 1, accurate for small t2 = t - t_lin
    return e_mid * (1.0 + shrink), t_lin * (e0 - 0.5 * a_max * t_lin) - e_mid * tau * shrink


def _airborne(n, e, d, vn, ve, vd, cn, ce, cd, t0, t, params: MultirotorParams, wind: Wind, xp=_Scalar):
    """Fly ``t`` s from time ``t0`` with the clamped command ``(cn, ce, cd)`` held, ignoring the ground:
    (n, e, d, vn, ve, vd, an, ae, ad) at ``t0 + t``."""
    tau = params.velocity_time_constant_s
    # Vertical: the error shrinks toward zero from either side.
    a_z = params.max_accel_z_mps2
    err = cd - vd
    sign = xp.copysign(1.0, err)
    e_t, integral = _track(abs(err), a_z, tau, t, xp)
    d1 = d + cd * t - sign * integral
    vd1 = cd - sign * e_t
    ad = sign * xp.minimum(a_z, e_t / tau)
    # Horizontal: the error shrinks along its initial direction (unit vector u; u = 0 without error).
    a_xy = params.max_accel_xy_mps2
    en, ee = cn - vn, ce - ve
    e0 = xp.hypot(en, ee)
    length = xp.where(e0 > 0.0, e0, 1.0)
    un, ue = en / length, ee / length
    e_t, integral = _track(e0, a_xy, tau, t, xp)
    n1, e1 = n + cn * t - un * integral, e + ce * t - ue * integral
    vn1, ve1 = cn - un * e_t, ce - ue * e_t
    accel = xp.minimum(a_xy, e_t / tau)
    gn, ge = _gust_drift(params, wind, t0, t0 + t, xp)
    return n1 + gn, e1 + ge, d1, vn1, ve1, vd1, un * accel, ue * accel, ad


def _gust_drift(params: MultirotorParams, wind: Wind, t0, t1, xp=_Scalar):
    """Horizontal displacement (north, east; m) over [t0, t1] by the gusts the controller lets through."""
    if wind.gust_mps == 0.0 or params.gust_response == 0.0:  # (parameters, not state: no per-vehicle if)
        return 0.0, 0.0
    north, east, _ = wind._terms
    r = params.gust_response
    return r * _axis_displacement(north, t0, t1, xp), r * _axis_displacement(east, t0, t1, xp)


def _turn_toward(yaw, target, max_rate: float, t, xp=_Scalar):
    """Heading after ``t`` s of turning toward the (wrapped) ``target`` at the max rate, shortest way."""
    diff = _wrap(target - yaw, xp)
    turn = max_rate * t
    return xp.where(abs(diff) <= turn, target, _wrap(yaw + xp.copysign(turn, diff), xp))


def _turn_at(yaw, rate, t, xp=_Scalar):
    """Heading after ``t`` s of turning at the (clamped) ``rate``."""
    return _wrap(yaw + rate * t, xp)


def _airborne_power_w(cn, ce, cd, params: MultirotorParams, wind: Wind, xp=_Scalar):
    """Power while flying a (clamped) command: hover + airspeed^2 + climb terms (steady wind only)."""
    airspeed2 = (cn - wind.north_mps) ** 2 + (ce - wind.east_mps) ** 2
    return (params.hover_power_w + params.power_per_airspeed2_w * airspeed2
            + params.climb_power_w_per_mps * xp.maximum(0.0, -cd))


def _battery_after(battery_wh, power_w, duration_s, xp=_Scalar):
    """Energy left after drawing ``power_w`` for ``duration_s`` (never below empty)."""
    return xp.maximum(0.0, battery_wh - power_w * duration_s / 3600.0)


# One vehicle, with ground contact and disarming (the SITL) ----------------------------------------
def _clamped(cmd: VelocityCommand, params: MultirotorParams) -> tuple:
    """The command's limited values as a plain tuple (north, east, down, yaw, yaw_rate).

    Non-finite numbers (NaN, inf) become 0 for velocities and yaw rate and ``None`` (hold heading)
    for an absolute yaw: a garbage setpoint should stop the vehicle, not point it anywhere.
    """
    n, e, d = _clamp_velocity(cmd.north_mps, cmd.east_mps, cmd.down_mps, params)
    yaw, rate = cmd.yaw_rad, cmd.yaw_rate_rad_s
    if yaw is not None:
        yaw = _wrap(yaw) if math.isfinite(yaw) else None
    if rate is not None:
        rate = _clamp_yaw_rate(rate, params)
    return n, e, d, yaw, rate


def clamp_command(cmd: VelocityCommand, params: MultirotorParams) -> VelocityCommand:
    """The command :func:`step` actually flies: speed, climb/descent and yaw-rate limits applied."""
    return VelocityCommand(*_clamped(cmd, params))


def _time_to_error(e0: float, e_target: float, a_max: float, tau: float) -> float:
    """Time for the error magnitude to shrink from ``e0`` to ``e_target`` (0 < e_target <= e0)."""
    e_knee = a_max * tau
    if e_target >= e_knee:
        return (e0 - e_target) / a_max
    t_knee = max(0.0, (e0 - e_knee) / a_max)
    return t_knee + tau * math.log(min(e0, e_knee) / e_target)


def _touchdown_time(d0: float, vd0: float, cd: float, a_max: float, tau: float, t_end: float) -> float | None:
    """First time in [0, t_end] the vertical trajectory reaches the ground, or None.

    The vertical velocity moves monotonically from ``vd0`` toward ``cd``, so ``down`` is convex or
    concave: we bracket the (single) upward crossing of 0 on a piece where ``down`` increases and
    polish it with safeguarded Newton steps (``d(down)/dt = vd``) to 1e-12 s.
    """
    err = cd - vd0
    sign, e0 = math.copysign(1.0, err), abs(err)

    def down_and_rate(s: float) -> tuple[float, float]:
        e_s, integral = _track(e0, a_max, tau, s)
        return d0 + cd * s - sign * integral, cd - sign * e_s

    d_end, vd_end = down_and_rate(t_end)
    if vd0 >= 0.0 and vd_end >= 0.0:  # descending throughout: down increases
        lo, hi = 0.0, t_end
        if d_end < 0.0:
            return None
    elif vd0 > 0.0 > vd_end:  # descent turning into climb: closest to the ground where vd = 0
        lo, hi = 0.0, _time_to_error(e0, -cd, a_max, tau)
        if down_and_rate(hi)[0] < 0.0:
            return None
    elif vd0 < 0.0 < vd_end:  # climb turning into descent: down increases after vd = 0
        if d_end < 0.0:
            return None
        lo, hi = _time_to_error(e0, cd, a_max, tau), t_end
    else:  # climbing or level throughout: down never increases
        return None
    if down_and_rate(lo)[0] >= 0.0:
        return lo
    s = hi
    for _ in range(100):
        d, vd = down_and_rate(s)
        lo, hi = (lo, s) if d >= 0.0 else (s, hi)
        newton = s - d / vd if vd > 0.0 else lo - 1.0
        nxt = newton if lo < newton < hi else 0.5 * (lo + hi)
        if abs(nxt - s) < 1e-13 or hi - lo < 1e-12:
            return nxt
        s = nxt
    return hi


def _may_touch_down(d, vd, cd, duration, xp=_Scalar):
    """False where the ground is surely out of reach: vd moves monotonically from vd toward cd, so the
    descent rate never exceeds max(vd, cd). Skips the root find in the common case (high above it)."""
    return d + xp.maximum(xp.maximum(vd, cd), 0.0) * duration >= 0.0


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
    return _airborne_power_w(cn, ce, cd, params, wind)


def _fly(n: float, e: float, d: float, vn: float, ve: float, vd: float, cn: float, ce: float, cd: float,
         t0: float, duration: float, params: MultirotorParams, wind: Wind) -> tuple:
    """Armed flight for up to ``duration`` s from time ``t0``: the shared airborne physics, cut short
    (and stopped: no sliding) at touchdown. Returns (time flown, n, e, d, vn, ve, vd, an, ae, ad, landed).
    """
    touchdown = None
    if _may_touch_down(d, vd, cd, duration):
        touchdown = _touchdown_time(d, vd, cd, params.max_accel_z_mps2, params.velocity_time_constant_s,
                                    duration)
    if touchdown is None:
        n, e, d, vn, ve, vd, an, ae, ad = _airborne(n, e, d, vn, ve, vd, cn, ce, cd, t0, duration, params, wind)
        return duration, n, e, min(d, 0.0), vn, ve, vd, an, ae, ad, False
    n, e, *_ = _airborne(n, e, d, vn, ve, vd, cn, ce, cd, t0, touchdown, params, wind)
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
    gn, ge = _gust_drift(params, wind, state.time_s, state.time_s + flown)
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
            battery = _battery_after(state.battery_wh, params.idle_power_w, dt_s)
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
    battery = _battery_after(state.battery_wh, _airborne_power_w(cn, ce, cd, params, wind), airborne_s)
    if airborne_s < dt_s:  # resting on the ground for the rest of the step
        battery = _battery_after(battery, params.idle_power_w, dt_s - airborne_s)
    yaw = state.yaw_rad  # no yaw command (and no yawing on the ground): hold
    if yaw_target is not None:
        yaw = _turn_toward(yaw, yaw_target, params.max_yaw_rate_rad_s, airborne_s)
    elif yaw_rate is not None:
        yaw = _turn_at(yaw, yaw_rate, airborne_s)
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
    cn, ce, cd = _clamp_velocity(np.asarray(cmd_north, np.float64), np.asarray(cmd_east, np.float64),
                                 np.asarray(cmd_down, np.float64), params, xp)
    cd = np.broadcast_to(cd, s.down_m.shape)
    for i in np.flatnonzero(_may_touch_down(s.down_m, s.vd_mps, cd, dt_s, xp)):
        if s.down_m[i] > 0.0 or _touchdown_time(float(s.down_m[i]), float(s.vd_mps[i]), float(cd[i]),
                                                params.max_accel_z_mps2, params.velocity_time_constant_s,
                                                dt_s) is not None:
            raise ValueError(f"step_batch: vehicle {i} (down_m={s.down_m[i]:.3f}, vd_mps={s.vd_mps[i]:.3f}) "
                             f"would touch the ground; step_batch models airborne flight only")
    n, e, d, vn, ve, vd, _, _, _ = _airborne(s.north_m, s.east_m, s.down_m, s.vn_mps, s.ve_mps, s.vd_mps,
                                             cn, ce, cd, t0_s, dt_s, params, wind, xp)
    battery = _battery_after(s.battery_wh, _airborne_power_w(cn, ce, cd, params, wind, xp), dt_s, xp)
    yaw = s.yaw_rad
    if cmd_yaw_rate_rad_s is not None:
        yaw = _turn_at(yaw, _clamp_yaw_rate(np.asarray(cmd_yaw_rate_rad_s, np.float64), params, xp), dt_s, xp)
    if cmd_yaw_rad is not None:  # where a target is given it wins over the rate, as in step()
        target = np.asarray(cmd_yaw_rad, np.float64)
        has_target = np.isfinite(target)
        target = _wrap(np.where(has_target, target, 0.0), xp)
        yaw = np.where(has_target, _turn_toward(s.yaw_rad, target, params.max_yaw_rate_rad_s, dt_s, xp), yaw)
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
