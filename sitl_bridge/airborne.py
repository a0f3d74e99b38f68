"""The airborne physics of the simulated multirotor, written once for one vehicle (floats) and N (numpy arrays).

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

Every function takes ``xp`` (``ScalarMath`` or numpy, see ``sitl_bridge/scalar_math.py``) and has no Python
``if`` on values. ``sitl_bridge/dynamics.py`` adds the ground, disarming and the batch API on top.
"""
from __future__ import annotations

import math

from sitl_bridge.multirotor import MultirotorParams
from sitl_bridge.scalar_math import ScalarMath, wrap_angle
from sitl_bridge.wind import Wind, gust_drift


def clamp_velocity(n, e, d, params: MultirotorParams, xp=ScalarMath):
    """Commanded velocity with non-finite parts zeroed (garbage stops the vehicle), the horizontal
    speed limited keeping the direction, and the climb/descent rates limited."""
    finite, where = xp.isfinite, xp.where
    n, e, d = where(finite(n), n, 0.0), where(finite(e), e, 0.0), where(finite(d), d, 0.0)
    limit = params.max_speed_xy_mps
    scale = limit / xp.maximum(xp.hypot(n, e), limit)  # exactly 1 within the limit
    return n * scale, e * scale, xp.clip(d, -params.max_speed_up_mps, params.max_speed_down_mps)


def clamp_yaw_rate(rate, params: MultirotorParams, xp=ScalarMath):
    """Yaw-rate command limited to the max yaw rate; non-finite becomes 0 (hold)."""
    limit = params.max_yaw_rate_rad_s
    return xp.where(xp.isfinite(rate), xp.clip(rate, -limit, limit), 0.0)


def track(e0, a_max: float, tau: float, t, xp=ScalarMath):
    """Velocity-error magnitude after ``t`` s, and its integral over [0, t], starting from ``e0 >= 0``.

    Phase 1 (error above ``a_max * tau``, where the first-order law would ask for more than ``a_max``)
    lasts ``t_lin``, clipped to [0, t]; the exponential phase 2 takes the rest (possibly 0 s).
    """
    t_lin = xp.clip((e0 - a_max * tau) / a_max, 0.0, t)
    e_mid = e0 - a_max * t_lin  # error when phase 1 ends (or at t)
    shrink = xp.expm1((t_lin - t) / tau)  # exp(-t2/tau) - 1, accurate for small t2 = t - t_lin
    return e_mid * (1.0 + shrink), t_lin * (e0 - 0.5 * a_max * t_lin) - e_mid * tau * shrink


def fly_airborne(n, e, d, vn, ve, vd, cn, ce, cd, t0, t, params: MultirotorParams, wind: Wind, xp=ScalarMath):
    """Fly ``t`` s from time ``t0`` with the clamped command ``(cn, ce, cd)`` held, ignoring the ground:
    (n, e, d, vn, ve, vd, an, ae, ad) at ``t0 + t``."""
    tau = params.velocity_time_constant_s
    # Vertical: the error shrinks toward zero from either side.
    a_z = params.max_accel_z_mps2
    err = cd - vd
    sign = xp.copysign(1.0, err)
    e_t, integral = track(abs(err), a_z, tau, t, xp)
    d1 = d + cd * t - sign * integral
    vd1 = cd - sign * e_t
    ad = sign * xp.minimum(a_z, e_t / tau)
    # Horizontal: the error shrinks along its initial direction (unit vector u; u = 0 without error).
    a_xy = params.max_accel_xy_mps2
    en, ee = cn - vn, ce - ve
    e0 = xp.hypot(en, ee)
    length = xp.where(e0 > 0.0, e0, 1.0)
    un, ue = en / length, ee / length
    e_t, integral = track(e0, a_xy, tau, t, xp)
    n1, e1 = n + cn * t - un * integral, e + ce * t - ue * integral
    vn1, ve1 = cn - un * e_t, ce - ue * e_t
    accel = xp.minimum(a_xy, e_t / tau)
    gn, ge = gust_drift(params, wind, t0, t0 + t, xp)
    return n1 + gn, e1 + ge, d1, vn1, ve1, vd1, un * accel, ue * accel, ad


def turn_toward(yaw, target, max_rate: float, t, xp=ScalarMath):
    """Heading after ``t`` s of turning toward the (wrapped) ``target`` at the max rate, shortest way."""
    diff = wrap_angle(target - yaw, xp)
    turn = max_rate * t
    return xp.where(abs(diff) <= turn, target, wrap_angle(yaw + xp.copysign(turn, diff), xp))


def turn_at(yaw, rate, t, xp=ScalarMath):
    """Heading after ``t`` s of turning at the (clamped) ``rate``."""
    return wrap_angle(yaw + rate * t, xp)


def airborne_power_w(cn, ce, cd, params: MultirotorParams, wind: Wind, xp=ScalarMath):
    """Power while flying a (clamped) command: hover + airspeed^2 + climb terms (steady wind only)."""
    airspeed2 = (cn - wind.north_mps) ** 2 + (ce - wind.east_mps) ** 2
    return (params.hover_power_w + params.power_per_airspeed2_w * airspeed2
            + params.climb_power_w_per_mps * xp.maximum(0.0, -cd))


def battery_after(battery_wh, power_w, duration_s, xp=ScalarMath):
    """Energy left after drawing ``power_w`` for ``duration_s`` (never below empty)."""
    return xp.maximum(0.0, battery_wh - power_w * duration_s / 3600.0)


def _time_to_error(e0: float, e_target: float, a_max: float, tau: float) -> float:
    """Time for the error magnitude to shrink from ``e0`` to ``e_target`` (0 < e_target <= e0)."""
    e_knee = a_max * tau
    if e_target >= e_knee:
        return (e0 - e_target) / a_max
    t_knee = max(0.0, (e0 - e_knee) / a_max)
    return t_knee + tau * math.log(min(e0, e_knee) / e_target)


def touchdown_time(d0: float, vd0: float, cd: float, a_max: float, tau: float, t_end: float) -> float | None:
    """First time in [0, t_end] the vertical trajectory reaches the ground, or None.

    The vertical velocity moves monotonically from ``vd0`` toward ``cd``, so ``down`` is convex or
    concave: we bracket the (single) upward crossing of 0 on a piece where ``down`` increases and
    polish it with safeguarded Newton steps (``d(down)/dt = vd``) to 1e-12 s.
    """
    err = cd - vd0
    sign, e0 = math.copysign(1.0, err), abs(err)

    def down_and_rate(s: float) -> tuple[float, float]:
        e_s, integral = track(e0, a_max, tau, s)
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


def may_touch_down(d, vd, cd, duration, xp=ScalarMath):
    """False where the ground is surely out of reach: vd moves monotonically from vd toward cd, so the
    descent rate never exceeds max(vd, cd). Skips the root find in the common case (high above it)."""
    return d + xp.maximum(xp.maximum(vd, cd), 0.0) * duration >= 0.0
