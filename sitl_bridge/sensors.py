"""Seeded sensor models of the simulated multirotor: GPS, barometer and attitude.

The SITL feeds the true state into :meth:`SensorSuite.update` at the physics rate (100-250 Hz) and
publishes what the suite reports, so the flight stack only ever sees noisy measurements, never
simulator ground truth.

Error models (all metres / radians, NED frame):

* GPS position = truth + slowly wandering bias + white noise. The bias is a first-order Gauss-Markov
  process per axis (steady-state std ``gps_bias_std_m``, time constant ``gps_bias_time_constant_s``);
  the white noise is independent per fix. Velocity has white noise only. Fixes arrive at
  ``gps_rate_hz`` on the fixed time grid ``k / gps_rate_hz``.
* Barometric altitude (above home, up positive) = truth + Gauss-Markov bias + white noise, every call.
* Attitude = truth + white noise (roll/pitch ``attitude_noise_rad``, yaw ``heading_noise_rad``).

Biases start in their steady state (drawn with the steady-state std), so the error statistics are the
same at t = 0 as an hour later. They are advanced with the exact discretisation of the process,
``b <- b * exp(-dt/T) + std * sqrt(1 - exp(-2 dt/T)) * N(0, 1)``, which is exact for any ``dt``:
that is why the GPS bias may be advanced only when a fix is taken without changing its statistics.

All randomness comes from one ``random.Random(seed)``: the same seed and the same sequence of
``update`` calls give bit-identical readings. ``random.Random.gauss`` is used rather than numpy
because drawing single scalars from numpy costs about ten times more per call.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, fields

from missions.validation import NON_NEGATIVE, POSITIVE, check_fields

_TWO_PI = 2.0 * math.pi
# Callers usually compute time as step * dt, which lands a few ulps either side of the GPS grid;
# without this slack a fix nominally due at 0.3 s could slip to the next physics step.
_GRID_TOLERANCE_S = 1e-9


@dataclass(frozen=True)
class SensorConfig:
    """Noise and timing of the simulated sensors. Every field is validated on construction.

    Attributes:
        gps_rate_hz: GPS fix rate in Hz, in [5, 10] (the rates real autopilot GPS receivers deliver).
        gps_horizontal_noise_m: std of the white noise on north and east, metres, per fix.
        gps_vertical_noise_m: std of the white noise on down, metres, per fix.
        gps_velocity_noise_mps: std of the white noise on each velocity axis, m/s, per fix.
        gps_bias_std_m: steady-state std of the wandering GPS position bias on each axis, metres.
        gps_bias_time_constant_s: correlation time of the GPS bias, seconds.
        baro_noise_m: std of the white noise on barometric altitude, metres, per reading.
        baro_bias_std_m: steady-state std of the wandering barometric bias, metres.
        baro_bias_time_constant_s: correlation time of the barometric bias, seconds.
        attitude_noise_rad: std of the white noise on roll and pitch, radians.
        heading_noise_rad: std of the white noise on yaw, radians.
    """

    gps_rate_hz: float = 10.0
    gps_horizontal_noise_m: float = 0.3
    gps_vertical_noise_m: float = 0.5
    gps_velocity_noise_mps: float = 0.05
    gps_bias_std_m: float = 0.5
    gps_bias_time_constant_s: float = 60.0
    baro_noise_m: float = 0.05
    baro_bias_std_m: float = 0.2
    baro_bias_time_constant_s: float = 120.0
    attitude_noise_rad: float = 0.002
    heading_noise_rad: float = 0.005

    def __post_init__(self) -> None:
        # Time constants divide (a bias with none would not wander but jump); a noise level may be 0 (off).
        check_fields(self, [("gps_rate_hz", 5.0, 10.0)]
                     + [(f.name, POSITIVE if f.name.endswith("time_constant_s") else NON_NEGATIVE)
                        for f in fields(self) if f.name != "gps_rate_hz"])


@dataclass(frozen=True)
class GpsFix:
    """One GPS measurement in the local NED frame around home.

    Attributes:
        time_s: simulation time at which the true state was sampled, seconds.
        north_m, east_m, down_m: measured position relative to home, metres.
        vn_mps, ve_mps, vd_mps: measured velocity, m/s.
        eph_m: 1-sigma horizontal error per axis (white noise and bias combined), metres; the
            value a Kalman filter should use as its measurement std.
        epv_m: 1-sigma vertical error (white noise and bias combined), metres.
        fix_type: GPS_FIX_TYPE (3 = 3D fix).
        satellites: number of satellites used.
    """

    time_s: float
    north_m: float
    east_m: float
    down_m: float
    vn_mps: float
    ve_mps: float
    vd_mps: float
    eph_m: float
    epv_m: float
    fix_type: int = 3
    satellites: int = 12


def wrap_pi(angle_rad: float) -> float:
    """Wrap an angle to (-pi, pi]."""
    wrapped = math.remainder(angle_rad, _TWO_PI)  # in [-pi, pi]
    return math.pi if wrapped == -math.pi else wrapped


def _gauss_markov_coefficients(dt_s: float, std: float, time_constant_s: float) -> tuple[float, float]:
    """(decay, drive std) of the exact one-step update of a first-order Gauss-Markov process."""
    decay = math.exp(-dt_s / time_constant_s)
    # -expm1(-x) is 1 - exp(-x) without cancellation when dt is a tiny fraction of T.
    return decay, std * math.sqrt(-math.expm1(-2.0 * dt_s / time_constant_s))


class SensorSuite:
    """GPS, barometer and attitude readings derived from the true vehicle state.

    Call :meth:`update` once per physics step with non-decreasing ``time_s``; then read:

    Attributes:
        gps: the latest fix, or None before the first one.
        gps_fix_count: number of fixes taken so far; it changes exactly when ``gps`` is a new fix.
        baro_alt_m: noisy altitude above home, metres, up positive (0.0 before the first update).
        attitude_rpy: noisy (roll, pitch, yaw) in radians, yaw wrapped to (-pi, pi].
    """

    __slots__ = (
        "config",
        "gps",
        "gps_fix_count",
        "baro_alt_m",
        "attitude_rpy",
        "_gauss",
        "_gps_rate_hz",
        "_gps_eph_m",
        "_gps_epv_m",
        "_gps_bias",
        "_gps_bias_time_s",
        "_next_fix_index",
        "_next_fix_time_s",
        "_last_time_s",
        "_baro_bias_m",
    )

    def __init__(self, config: SensorConfig = SensorConfig(), seed: int = 0) -> None:
        """Create the suite; ``seed`` fixes every random draw it will ever make."""
        self.config = config
        self._gauss = random.Random(seed).gauss
        gauss = self._gauss
        self.gps: GpsFix | None = None
        self.gps_fix_count = 0
        self.baro_alt_m = 0.0
        self.attitude_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)

        self._gps_rate_hz = config.gps_rate_hz
        self._gps_eph_m = math.hypot(config.gps_horizontal_noise_m, config.gps_bias_std_m)
        self._gps_epv_m = math.hypot(config.gps_vertical_noise_m, config.gps_bias_std_m)
        # Biases start in steady state, so error statistics do not depend on the time since start.
        self._gps_bias = [gauss(0.0, config.gps_bias_std_m) for _ in range(3)]
        self._gps_bias_time_s: float | None = None
        self._next_fix_index = 0
        self._next_fix_time_s = 0.0
        self._last_time_s: float | None = None
        self._baro_bias_m = gauss(0.0, config.baro_bias_std_m)

    @property
    def gps_bias_ned_m(self) -> tuple[float, float, float]:
        """Current GPS position bias (north, east, down) in metres, as of the latest fix.

        Simulator truth for tests and diagnostics; the flight stack must not read it.
        """
        north, east, down = self._gps_bias
        return (north, east, down)

    def update(
        self,
        time_s: float,
        position_ned: tuple[float, float, float],
        velocity_ned: tuple[float, float, float],
        attitude_rpy: tuple[float, float, float],
    ) -> None:
        """Advance the sensors to ``time_s`` given the true state at that time.

        Updates the barometer and attitude readings on every call, and takes a GPS fix on the first
        call at or after each grid time ``k / gps_rate_hz`` (at most one fix per call; grid times
        skipped by a step longer than the GPS period are dropped, as a receiver would).
        """
        last = self._last_time_s
        dt = 0.0 if last is None else time_s - last
        if dt < 0.0:
            raise ValueError(f"time_s must not decrease: got {time_s!r} after {last!r}")
        self._last_time_s = time_s
        gauss = self._gauss
        config = self.config

        # Recomputed every call: caching on dt rarely hits, because step * dt times differ by ulps.
        decay, drive = _gauss_markov_coefficients(dt, config.baro_bias_std_m, config.baro_bias_time_constant_s)
        self._baro_bias_m = self._baro_bias_m * decay + gauss(0.0, drive)
        self.baro_alt_m = -position_ned[2] + self._baro_bias_m + gauss(0.0, config.baro_noise_m)

        roll, pitch, yaw = attitude_rpy
        self.attitude_rpy = (
            roll + gauss(0.0, config.attitude_noise_rad),
            pitch + gauss(0.0, config.attitude_noise_rad),
            wrap_pi(yaw + gauss(0.0, config.heading_noise_rad)),
        )

        if time_s + _GRID_TOLERANCE_S >= self._next_fix_time_s:
            self._take_fix(time_s, position_ned, velocity_ned)

    def _take_fix(
        self,
        time_s: float,
        position_ned: tuple[float, float, float],
        velocity_ned: tuple[float, float, float],
    ) -> None:
        """Advance the GPS bias to ``time_s``, sample a fix and schedule the next grid time."""
        config = self.config
        gauss = self._gauss
        last = self._gps_bias_time_s
        if last is not None:
            # Exact over any interval, so advancing only at fix times keeps the bias statistics.
            decay, drive = _gauss_markov_coefficients(
                time_s - last, config.gps_bias_std_m, config.gps_bias_time_constant_s
            )
            self._gps_bias = [b * decay + gauss(0.0, drive) for b in self._gps_bias]
        self._gps_bias_time_s = time_s

        bias_n, bias_e, bias_d = self._gps_bias
        north, east, down = position_ned
        vn, ve, vd = velocity_ned
        h_noise = config.gps_horizontal_noise_m
        v_noise = config.gps_velocity_noise_mps
        self.gps = GpsFix(
            time_s=time_s,
            north_m=north + bias_n + gauss(0.0, h_noise),
            east_m=east + bias_e + gauss(0.0, h_noise),
            down_m=down + bias_d + gauss(0.0, config.gps_vertical_noise_m),
            vn_mps=vn + gauss(0.0, v_noise),
            ve_mps=ve + gauss(0.0, v_noise),
            vd_mps=vd + gauss(0.0, v_noise),
            eph_m=self._gps_eph_m,
            epv_m=self._gps_epv_m,
        )
        self.gps_fix_count += 1

        # Next grid point strictly after this one; computed as k / rate (not by adding periods)
        # so that the schedule never drifts.
        passed = math.floor((time_s + _GRID_TOLERANCE_S) * self._gps_rate_hz)  # last grid index reached
        index = max(self._next_fix_index + 1, passed + 1)
        self._next_fix_index = index
        self._next_fix_time_s = index / self._gps_rate_hz
