"""Multirotor dynamics: a 3-D point mass behind a velocity controller, with wind, battery and ground.

Everything here is a pure function over frozen dataclasses: no I/O, no global randomness, no numpy
(the SITL calls :func:`step` at 100-250 Hz in pure Python, and float/``math`` is several times faster
than numpy on scalars).

The model, per axis group (horizontal = 2-D vector, vertical = 1-D):

* The controller's velocity ``v`` tracks the (clamped) command ``c`` as a first-order lag with time
  constant ``tau``, i.e. ``dv/dt = (c - v) / tau``, except that ``|dv/dt|`` is capped at ``a_max``.
  With ``c`` constant the error ``e = c - v`` keeps its direction and its magnitude follows
  phase 1 (``|e| > a_max * tau``): linear decrease at ``a_max``; phase 2: ``|e| = |e0| exp(-t / tau)``.
  Both phases have closed-form position integrals, so :func:`step` is EXACT for any step size: one
  1 s step equals 100 steps of 10 ms to rounding error. Every other ingredient is chosen to keep that
  property (gusts are a function of absolute time, power is constant while the command is, touchdown
  is found by a root find on the closed-form trajectory, the stored acceleration is instantaneous).
* Wind: the velocity controller fully rejects the steady wind (it holds ground velocity) and a
  fraction ``gust_response`` of the horizontal gusts leaks through as ground velocity. The altitude
  loop is modelled as rejecting vertical gusts entirely (a multirotor's thrust acts directly on that
  axis), which also means a gust can never push a vehicle through the ground.
* Ground: flat at ``down = 0``. On the ground (armed, no climb command) the vehicle rests: zero
  velocity, no sliding, no yawing. A climb command lifts off from rest. While armed, touching the
  ground ends the flight for the rest of the step (or lifts off again at once if the command climbs).
* Disarmed: motors off. On the ground nothing but time moves; in the air the vehicle falls
  ballistically (gravity, no drag, horizontal velocity kept, gusts still drift it) until it hits the
  ground. The autopilot is not expected to disarm in the air; this only keeps the state consistent.
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass, field

GRAVITY_MPS2 = 9.80665
GUSTS_PER_AXIS = 3
GUST_PERIOD_RANGE_S = (3.0, 30.0)
VERTICAL_GUST_FRACTION = 0.3  # vertical gusts are this fraction of the horizontal ones
_TWO_PI = 2.0 * math.pi


def _wrap(angle_rad: float) -> float:
    """Wrap an angle to (-pi, pi]."""
    wrapped = math.remainder(angle_rad, _TWO_PI)  # in [-pi, pi]
    return math.pi if wrapped == -math.pi else wrapped


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
        north, east, down = self._terms
        return _axis_displacement(north, t0_s, t1_s), _axis_displacement(east, t0_s, t1_s), \
            _axis_displacement(down, t0_s, t1_s)

    def horizontal_gust_displacement(self, t0_s: float, t1_s: float) -> tuple[float, float]:
        """North and east parts of :meth:`gust_displacement` (the hot path needs only these)."""
        return _axis_displacement(self._terms[0], t0_s, t1_s), _axis_displacement(self._terms[1], t0_s, t1_s)


def _axis_displacement(terms: tuple, t0_s: float, t1_s: float) -> float:
    """Integral over [t0, t1] of sum(a * sin(w t + ph)) = sum(a / w * (cos(w t0 + ph) - cos(w t1 + ph)))."""
    cos = math.cos
    total = 0.0
    for _, w, ph, a_over_w in terms:  # a plain loop: measurably faster than sum() over a generator
        total += a_over_w * (cos(w * t0_s + ph) - cos(w * t1_s + ph))
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


_Clamped = tuple[float, float, float, float | None, float | None]


def _clamped(cmd: VelocityCommand, params: MultirotorParams) -> _Clamped:
    """The command's limited values as a plain tuple (north, east, down, yaw, yaw_rate).

    Non-finite numbers (NaN, inf) become 0 for velocities and yaw rate and ``None`` (hold heading)
    for an absolute yaw: a garbage setpoint should stop the vehicle, not point it anywhere.
    """
    n, e, d = cmd.north_mps, cmd.east_mps, cmd.down_mps
    n = n if math.isfinite(n) else 0.0
    e = e if math.isfinite(e) else 0.0
    d = d if math.isfinite(d) else 0.0
    speed = math.hypot(n, e)
    if speed > params.max_speed_xy_mps:  # scale the vector so the direction is kept
        scale = params.max_speed_xy_mps / speed
        n, e = n * scale, e * scale
    d = min(max(d, -params.max_speed_up_mps), params.max_speed_down_mps)
    yaw, rate = cmd.yaw_rad, cmd.yaw_rate_rad_s
    if yaw is not None:
        yaw = _wrap(yaw) if math.isfinite(yaw) else None
    if rate is not None:
        limit = params.max_yaw_rate_rad_s
        rate = min(max(rate, -limit), limit) if math.isfinite(rate) else 0.0
    return n, e, d, yaw, rate


def clamp_command(cmd: VelocityCommand, params: MultirotorParams) -> VelocityCommand:
    """The command :func:`step` actually flies: speed, climb/descent and yaw-rate limits applied."""
    return VelocityCommand(*_clamped(cmd, params))


def _track(e0: float, a_max: float, tau: float, t: float) -> tuple[float, float]:
    """Velocity-error magnitude after ``t`` s, and its integral over [0, t], starting from ``e0``."""
    e_knee = a_max * tau  # above this, the first-order law would ask for more than a_max
    integral = 0.0
    if e0 > e_knee:  # phase 1: constant acceleration a_max
        t_knee = (e0 - e_knee) / a_max
        if t <= t_knee:
            return e0 - a_max * t, t * (e0 - 0.5 * a_max * t)
        integral = 0.5 * (e0 + e_knee) * t_knee
        t -= t_knee
        e0 = e_knee
    shrink = math.expm1(-t / tau)  # exp(-t/tau) - 1, accurate for small t
    return e0 * (1.0 + shrink), integral - e0 * tau * shrink  # phase 2: exponential decay


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
        if d >= 0.0:
            hi = s
        else:
            lo = s
        newton = s - d / vd if vd > 0.0 else lo - 1.0
        nxt = newton if lo < newton < hi else 0.5 * (lo + hi)
        if abs(nxt - s) < 1e-13 or hi - lo < 1e-12:
            return nxt
        s = nxt
    return hi


def _yaw_after(yaw: float, target: float | None, rate: float | None, max_rate: float, t: float) -> float:
    """Heading after ``t`` s of turning toward ``target`` (shortest way) or at ``rate``."""
    if target is not None:
        diff = _wrap(target - yaw)
        turn = max_rate * t
        return target if abs(diff) <= turn else _wrap(yaw + math.copysign(turn, diff))
    if rate:
        return _wrap(yaw + rate * t)
    return yaw


def _airborne_power_w(cn: float, ce: float, cd: float, params: MultirotorParams, wind: Wind) -> float:
    """Power while flying a (clamped) command: hover + airspeed^2 + climb terms (steady wind only)."""
    airspeed2 = (cn - wind.north_mps) ** 2 + (ce - wind.east_mps) ** 2
    return (params.hover_power_w + params.power_per_airspeed2_w * airspeed2
            + params.climb_power_w_per_mps * max(0.0, -cd))


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
    """Armed flight for up to ``duration`` s from time ``t0``; stops at touchdown.

    Returns (time flown, n, e, d, vn, ve, vd, an, ae, ad, touched_down).
    """
    tau = params.velocity_time_constant_s
    a_z = params.max_accel_z_mps2
    flown = duration
    touchdown = None
    # vd moves monotonically from vd toward cd, so the descent rate never exceeds max(vd, cd): skip the
    # root find (the common case, well above the ground) when even that cannot reach the ground.
    if d + max(vd, cd, 0.0) * duration >= 0.0:
        touchdown = _touchdown_time(d, vd, cd, a_z, tau, duration)
    if touchdown is not None:
        flown = touchdown
        d1, vd1, ad = 0.0, 0.0, 0.0
    else:
        err = cd - vd
        sign = math.copysign(1.0, err)
        e_t, integral = _track(abs(err), a_z, tau, flown)
        d1 = min(0.0, d + cd * flown - sign * integral)
        vd1 = cd - sign * e_t
        ad = sign * min(a_z, e_t / tau)
    # Horizontal: the error shrinks along its initial direction.
    en, ee = cn - vn, ce - ve
    e0 = math.hypot(en, ee)
    n1, e1 = n + cn * flown, e + ce * flown
    if e0 > 0.0:
        un, ue = en / e0, ee / e0
        e_t, integral = _track(e0, params.max_accel_xy_mps2, tau, flown)
        n1, e1 = n1 - un * integral, e1 - ue * integral
        vn1, ve1 = cn - un * e_t, ce - ue * e_t
        accel = min(params.max_accel_xy_mps2, e_t / tau)
        an, ae = un * accel, ue * accel
    else:
        vn1, ve1, an, ae = cn, ce, 0.0, 0.0
    if wind.gust_mps > 0.0 and params.gust_response > 0.0:
        gn, ge = wind.horizontal_gust_displacement(t0, t0 + flown)
        n1 += params.gust_response * gn
        e1 += params.gust_response * ge
    if touchdown is not None:  # no sliding: the ground stops the vehicle
        vn1, ve1, an, ae = 0.0, 0.0, 0.0, 0.0
    return flown, n1, e1, d1, vn1, ve1, vd1, an, ae, ad, touchdown is not None


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
    n1, e1 = state.north_m + state.vn_mps * flown, state.east_m + state.ve_mps * flown
    if wind.gust_mps > 0.0 and params.gust_response > 0.0:
        gn, ge = wind.horizontal_gust_displacement(state.time_s, state.time_s + flown)
        n1 += params.gust_response * gn
        e1 += params.gust_response * ge
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
            battery = max(0.0, state.battery_wh - params.idle_power_w * dt_s / 3600.0)
            return VehicleState(t0 + dt_s, state.north_m, state.east_m, 0.0, 0.0, 0.0, 0.0, state.yaw_rad,
                                0.0, 0.0, 0.0, battery, True)
        # Lift off from rest.
        flight = _fly(state.north_m, state.east_m, 0.0, 0.0, 0.0, 0.0, cn, ce, cd, t0, dt_s, params, wind)
    else:
        flight = _fly(state.north_m, state.east_m, min(state.down_m, 0.0), state.vn_mps, state.ve_mps,
                      state.vd_mps, cn, ce, cd, t0, dt_s, params, wind)
    flown, n, e, d, vn, ve, vd, an, ae, ad, landed = flight
    airborne_s = flown
    if landed and climbing and flown < dt_s:
        # Touched down while still commanded to climb (e.g. braking a descent too close to the
        # ground): lift off again at once, exactly as the next step would.
        flight = _fly(n, e, 0.0, 0.0, 0.0, 0.0, cn, ce, cd, t0 + flown, dt_s - flown, params, wind)
        _, n, e, d, vn, ve, vd, an, ae, ad, landed = flight
        airborne_s = dt_s
    energy_wh = (_airborne_power_w(cn, ce, cd, params, wind) * airborne_s
                 + params.idle_power_w * (dt_s - airborne_s)) / 3600.0
    yaw = _yaw_after(state.yaw_rad, yaw_target, yaw_rate, params.max_yaw_rate_rad_s, airborne_s)
    battery = max(0.0, state.battery_wh - energy_wh)
    return VehicleState(t0 + dt_s, n, e, d, vn, ve, vd, yaw, an, ae, ad, battery, landed)


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
