"""The mission runner's pose estimator: a filterpy Kalman filter over position/velocity telemetry.

The runner feeds every LOCAL_POSITION_NED and/or GLOBAL_POSITION_INT it hears and asks
:meth:`PoseEstimator.predict_to` for the pose at its control time; the policy sees that filtered pose,
never simulator truth. State: NED position and velocity (plus acceleration for the constant-acceleration
model), metres relative to home. Time is the vehicle's ``time_boot_ms`` (by default), or that stamp mapped
onto the runner's clock by :mod:`autonomy.vehicle_time` (the runner's case: it predicts to its own clock), never
a message's arrival time, so link latency does not distort the steps and replays are reproducible.

How each message is handled (every outcome is counted, so the runner can log it):

* the first measurement initialises the state (covariance: the source's own measurement variances);
* a message stamped like the last one processed from the same source is a duplicate: ignored;
* a message older than the filter time by more than ``late_tolerance_s`` is late: ignored. There is no
  retrodiction (re-running the filter from the past): at 10-50 Hz telemetry a late message carries
  almost nothing the next one will not, so dropping it is the simplest correct choice;
* dropped messages need nothing special: the next predict step is longer and its process noise larger;
* outliers fail the innovation gate (Mahalanobis distance y' S^-1 y above a chi-square threshold) and
  are ignored; a measurement failing the gate after ``max_consecutive_rejections`` rejections in a row
  re-initialises the filter: the vehicle (or its GPS reference) really moved, and the model was wrong;
* time going back by more than ``reboot_backstep_s`` (a reboot, or the uint32 ``time_boot_ms`` wrapping
  after 49.7 days) and a silence longer than ``max_message_age_s`` also re-initialise from the message.

Both messages normally come from the same autopilot estimate, so their errors are not independent:
fusing both makes the filter over-confident (up to sqrt(2) in std). Feed one where you can
(LOCAL_POSITION_NED, which needs no home point).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Callable

import numpy as np
from filterpy.kalman import KalmanFilter

from missions.geodesy import GeoPoint, LocalFrame
from missions.validation import COUNT, NON_NEGATIVE, POSITIVE, check_in

LOCAL_POSITION_NED = "LOCAL_POSITION_NED"
GLOBAL_POSITION_INT = "GLOBAL_POSITION_INT"
MODELS = {"constant_velocity": 2, "constant_acceleration": 3}  # model -> state terms per axis
# Constant-acceleration model only: nothing measures acceleration, so start with a multirotor's typical
# manoeuvring range rather than zero uncertainty.
INITIAL_ACCELERATION_STD_MPS2 = 3.0


@dataclass(frozen=True)
class EstimatorConfig:
    """Filter model and noise levels, validated on construction (docs/estimator.md says why these defaults).

    Attributes:
        model: "constant_velocity" (state n, e, d, vn, ve, vd) or "constant_acceleration" (adds an, ae, ad).
        process_noise_psd: spectral density of the white noise driving the model: acceleration (m^2/s^3)
            for constant_velocity, jerk (m^2/s^5) for constant_acceleration. 2.0: velocity may drift by
            ~1.4 m/s in a second, as a multirotor's turns and stops at search speed need.
        local_position_std_m, local_velocity_std_mps: LOCAL_POSITION_NED noise per axis (m, m/s): 0.5 m
            (GPS white noise ~0.3 m plus part of its wandering bias) and 0.1 m/s (GPS Doppler).
        global_position_std_m, global_velocity_std_mps: GLOBAL_POSITION_INT noise per axis: the same
            estimate, converted through a home point and an AMSL altitude, so a little larger (0.7 m,
            0.15 m/s); its 1e-7 deg / mm / cm/s quantisation is negligible beside that.
        innovation_gate_chi2: a measurement is an outlier when y' S^-1 y exceeds this; 22.46 is the
            99.9 % chi-square quantile for 6 degrees of freedom (3 positions + 3 velocities).
        max_consecutive_rejections: rejections in a row after which the next gate failure re-initialises
            the filter (5: half a second at 10 Hz, longer than any single glitch).
        converged_position_std_m, converged_min_updates: ``converged`` needs every position std at most
            this (m) and at least this many fused measurements since the last (re)initialisation.
        late_tolerance_s: a message at most this much older than the filter time is fused as if current
            (the autopilot stamps its two position messages ms apart; 20 ms at 5 m/s is 10 cm).
        reboot_backstep_s: time going back by more than this means a reboot or a wrap: re-initialise.
        max_message_age_s: a silence longer than this re-initialises on the next message, and
            :meth:`PoseEstimator.predict_to` flags older estimates as stale.
    """

    model: str = "constant_velocity"
    process_noise_psd: float = 2.0
    local_position_std_m: float = 0.5
    local_velocity_std_mps: float = 0.1
    global_position_std_m: float = 0.7
    global_velocity_std_mps: float = 0.15
    innovation_gate_chi2: float = 22.46
    max_consecutive_rejections: int = 5
    converged_position_std_m: float = 1.0
    converged_min_updates: int = 10
    late_tolerance_s: float = 0.02
    reboot_backstep_s: float = 3.0
    max_message_age_s: float = 2.0

    def __post_init__(self) -> None:
        if not (isinstance(self.model, str) and self.model in MODELS):
            raise ValueError(f"EstimatorConfig.model must be one of {sorted(MODELS)}, got {self.model!r}; "
                             f"try the default 'constant_velocity'")
        # The defaults are sound for any autopilot's telemetry, so an error suggests the default to go back to.
        allowed = {"max_consecutive_rejections": COUNT, "converged_min_updates": COUNT,
                   "late_tolerance_s": NON_NEGATIVE}
        for option in (f for f in fields(self) if f.name != "model"):
            check_in("EstimatorConfig", option.name, getattr(self, option.name), allowed.get(option.name, POSITIVE),
                     hint=f"; try the default {option.default!r}")
        if self.late_tolerance_s >= self.reboot_backstep_s:
            raise ValueError(f"EstimatorConfig.late_tolerance_s must be below reboot_backstep_s "
                             f"({self.reboot_backstep_s!r}), got {self.late_tolerance_s!r}; try the default 0.02")


@dataclass(frozen=True)
class PoseEstimate:
    """The filtered pose at one vehicle time (seconds since boot), NED metres relative to home.

    ``covariance`` is the full state covariance; ``age_s`` the time since the last fused measurement,
    ``stale`` whether that exceeds ``max_message_age_s`` (the runner should hold rather than trust it).
    """

    time_s: float
    position_ned: np.ndarray
    velocity_ned: np.ndarray
    age_s: float
    stale: bool
    predict_covariance: Callable[[], np.ndarray] = field(repr=False, compare=False)
    """Works the covariance out when asked: the runner predicts every tick and reads only the pose."""

    @property
    def covariance(self) -> np.ndarray:
        return self.predict_covariance()


class PoseEstimator:
    """Kalman filter over LOCAL_POSITION_NED / GLOBAL_POSITION_INT (see the module notes).

    ``home`` (the vehicle's HOME_POSITION) is needed only for GLOBAL_POSITION_INT, whose lat/lon/alt are
    converted to local NED with :mod:`missions.geodesy`, the same conversion the simulator uses.
    """

    def __init__(self, config: EstimatorConfig = EstimatorConfig(), home: GeoPoint | None = None) -> None:
        self.config = config
        self._frame = LocalFrame(home) if home is not None else None
        self.origin = home
        """The geodetic origin of the NED frame (the ``home`` given), or None."""
        self._order = MODELS[config.model]
        self._kf = KalmanFilter(dim_x=3 * self._order, dim_z=6)
        self._kf.H = np.eye(6, 3 * self._order)  # we measure position and velocity, not acceleration
        self._filter_changes = 0  # counts every change of the filter's state (predict_to's answer is kept until one)
        self._std = {LOCAL_POSITION_NED: (config.local_position_std_m, config.local_velocity_std_mps),
                     GLOBAL_POSITION_INT: (config.global_position_std_m, config.global_velocity_std_mps)}
        self._time_s: float | None = None  # time of the filter state
        self._last_fused_s = 0.0
        self._last_seen_s: dict[str, float] = {}  # per source, for duplicates
        self._rejections_in_a_row = 0
        self._updates_since_init = 0
        self.accepted = self.rejected_outliers = self.ignored_stale = 0
        self.ignored_duplicates = self.ignored_invalid = self.reinitialisations = 0
        self.last_reinit_reason = ""
        self._pending_reason = ""  # why the next initialisation is a re-initialisation (restart)
        self._predicted: tuple[tuple, PoseEstimate] | None = None  # the last prediction and what it was made from
        axes = np.arange(3)
        self._identity = np.eye(3 * self._order)
        self._dt_entries = (np.concatenate([3 * i + axes for i in range(self._order - 1)]),
                            np.concatenate([3 * (i + 1) + axes for i in range(self._order - 1)]))
        self._half_dt2_entries = (axes, 6 + axes)
        self._blocks = (np.array([3 * i + axes for i in range(self._order) for _ in range(self._order)]).ravel(),
                        np.array([3 * j + axes for _ in range(self._order) for j in range(self._order)]).ravel())

    def update_local_position_ned(self, msg, time_s: float | None = None) -> str:
        """Fuse a pymavlink LOCAL_POSITION_NED message; returns the outcome (see :meth:`update`). ``time_s``: the
        message's time on the caller's clock (default: its time_boot_ms; see autonomy.vehicle_time)."""
        return self.update(msg.time_boot_ms / 1000.0 if time_s is None else time_s, (msg.x, msg.y, msg.z),
                           (msg.vx, msg.vy, msg.vz), LOCAL_POSITION_NED)

    def update_global_position_int(self, msg, time_s: float | None = None) -> str:
        """Fuse a pymavlink GLOBAL_POSITION_INT message (degE7, mm, cm/s); needs ``home``. ``time_s`` as for
        :meth:`update_local_position_ned`."""
        if self._frame is None:
            raise ValueError("PoseEstimator needs home=GeoPoint(...) (from HOME_POSITION) to fuse GLOBAL_POSITION_INT")
        position = self._frame.to_ned(msg.lat / 1e7, msg.lon / 1e7, msg.alt / 1000.0)
        return self.update(msg.time_boot_ms / 1000.0 if time_s is None else time_s, position,
                           (msg.vx / 100.0, msg.vy / 100.0, msg.vz / 100.0), GLOBAL_POSITION_INT)

    def restart(self, reason: str) -> None:
        """Forget the state: the next measurement re-initialises the filter (counted, with ``reason``). For a
        vehicle whose timeline changed (a reboot): its old pose says nothing about the new one."""
        if self._time_s is not None:
            self._time_s = None
            self._pending_reason = reason

    def update(self, time_s: float, position_ned, velocity_ned, source: str) -> str:
        """Fuse one measurement taken at vehicle time ``time_s`` (s since boot) from ``source``.

        Returns "initialised", "reinitialised", "accepted", "rejected", "duplicate", "stale" or "invalid".
        """
        if source not in self._std:
            raise ValueError(f"source must be {LOCAL_POSITION_NED!r} or {GLOBAL_POSITION_INT!r}, got {source!r}")
        z = np.concatenate([np.asarray(position_ned, float).reshape(3), np.asarray(velocity_ned, float).reshape(3)])
        if not (math.isfinite(time_s) and np.all(np.isfinite(z))):
            self.ignored_invalid += 1  # autopilots send NaN for fields they do not have
            return "invalid"
        if self._time_s is None:
            reason, self._pending_reason = self._pending_reason, ""
            return self._initialise(time_s, z, source, reason=reason)
        if self._last_seen_s.get(source) == time_s:
            self.ignored_duplicates += 1
            return "duplicate"
        cfg = self.config
        dt = time_s - self._time_s
        if dt < -cfg.reboot_backstep_s:
            return self._initialise(time_s, z, source, f"time went back {-dt:.1f} s (reboot or time_boot_ms wrap)")
        if dt > cfg.max_message_age_s:
            return self._initialise(time_s, z, source, f"no measurement for {dt:.1f} s")
        if dt < -cfg.late_tolerance_s:
            self.ignored_stale += 1
            return "stale"
        self._last_seen_s[source] = time_s
        if dt > 0.0:  # a dropped message just makes this step longer, and its process noise larger
            F, Q = self._transition(dt)
            self._kf.predict(F=F, Q=Q)
            self._filter_changes += 1
            self._time_s = time_s
        R = self._measurement_covariance(source)
        H, x, P = self._kf.H, self._kf.x[:, 0], self._kf.P
        y = z - H @ x  # innovation, and its covariance S; gate on the squared Mahalanobis distance
        if float(y @ np.linalg.solve(H @ P @ H.T + R, y)) > cfg.innovation_gate_chi2:
            if self._rejections_in_a_row >= cfg.max_consecutive_rejections:
                return self._initialise(time_s, z, source, f"{self._rejections_in_a_row + 1} outliers in a row")
            self._rejections_in_a_row += 1
            self.rejected_outliers += 1
            return "rejected"
        self._kf.update(z, R=R)
        self._filter_changes += 1
        self._rejections_in_a_row = 0
        self._updates_since_init += 1
        self._last_fused_s = time_s
        self.accepted += 1
        return "accepted"

    def predict_to(self, time_s: float) -> PoseEstimate:
        """The estimate at vehicle time ``time_s``, leaving the filter unchanged.

        The filter is not advanced, so telemetry stamped before ``time_s`` that arrives later still fuses.
        A time before the filter's own gives the current estimate (no retrodiction).
        """
        if self._time_s is None:
            raise RuntimeError("PoseEstimator has no estimate yet; feed it telemetry first")
        # asked many times a tick (the runner's guards, a fleet's separation shield): the same answer until the
        # filter or the time changes
        key = (time_s, self._filter_changes)
        if self._predicted is not None and self._predicted[0] == key:
            return self._predicted[1]
        dt = max(0.0, time_s - self._time_s)
        F = self._state_transition(dt)
        x = F @ self._kf.x[:, 0]
        P = self._kf.P  # filterpy replaces P on every change, so this one stays the covariance at the filter time
        age_s = self._time_s + dt - self._last_fused_s
        estimate = PoseEstimate(self._time_s + dt, x[:3], x[3:6], age_s, age_s > self.config.max_message_age_s,
                                lambda: F @ P @ F.T + self._process_noise(dt))
        self._predicted = (key, estimate)
        return estimate

    @property
    def time_s(self) -> float | None:
        """Vehicle time of the filter state (the last measurement processed), or None before the first."""
        return self._time_s

    @property
    def position_ned(self) -> np.ndarray:
        """Filtered NED position at :attr:`time_s`, metres relative to home."""
        return self._kf.x[:3, 0].copy()

    @property
    def velocity_ned(self) -> np.ndarray:
        """Filtered NED velocity at :attr:`time_s`, m/s."""
        return self._kf.x[3:6, 0].copy()

    @property
    def covariance(self) -> np.ndarray:
        """Full state covariance at :attr:`time_s` (position block first)."""
        return self._kf.P.copy()

    @property
    def converged(self) -> bool:
        """Enough fused measurements since (re)initialisation and every position std small enough."""
        if self._time_s is None or self._updates_since_init < self.config.converged_min_updates:
            return False
        return float(np.sqrt(np.diag(self._kf.P)[:3]).max()) <= self.config.converged_position_std_m

    def counters(self) -> dict[str, int]:
        """The message counters, for the runner's log."""
        return {name: getattr(self, name) for name in ("accepted", "rejected_outliers", "ignored_stale",
                                                       "ignored_duplicates", "ignored_invalid", "reinitialisations")}

    def _transition(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """(F, Q) for a step of dt seconds; the state is ordered [all positions, all velocities, ...]: each entry of
        the one-axis matrices becomes a 3 x 3 diagonal block, as ``np.kron(one_axis, np.eye(3))`` and filterpy's
        ``Q_continuous_white_noise(..., block_size=3, order_by_dim=False)`` place them (written out: asked for on
        every tick, those two cost more than the rest of the filter)."""
        return self._state_transition(dt), self._process_noise(dt)

    def _state_transition(self, dt: float) -> np.ndarray:
        """F of :meth:`_transition`: the identity with dt (and dt^2 / 2) in the blocks above the diagonal."""
        F = self._identity.copy()
        F[self._dt_entries] = dt
        if self._order == 3:
            F[self._half_dt2_entries] = 0.5 * dt * dt
        return F

    def _process_noise(self, dt: float) -> np.ndarray:
        """Q of :meth:`_transition`."""
        if self._order == 2:
            noise = np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
        else:
            noise = np.array([[dt**5 / 20.0, dt**4 / 8.0, dt**3 / 6.0], [dt**4 / 8.0, dt**3 / 3.0, dt**2 / 2.0],
                              [dt**3 / 6.0, dt**2 / 2.0, dt]])
        return self._spread(noise) * self.config.process_noise_psd

    def _spread(self, one_axis: np.ndarray) -> np.ndarray:
        """A one-axis matrix with each entry made a 3 x 3 diagonal block (``np.kron(one_axis, np.eye(3))``)."""
        rows, cols = self._blocks
        spread = np.zeros((3 * self._order, 3 * self._order))
        spread[rows, cols] = np.repeat(one_axis.ravel(), 3)
        return spread

    def _measurement_covariance(self, source: str) -> np.ndarray:
        position_std, velocity_std = self._std[source]
        return np.diag([position_std**2] * 3 + [velocity_std**2] * 3)

    def _initialise(self, time_s: float, z: np.ndarray, source: str, reason: str) -> str:
        """Set the state to the measurement, with the source's own variances as the uncertainty."""
        x = np.zeros(3 * self._order)
        x[:6] = z
        variances = np.diag(self._measurement_covariance(source))
        extra = [INITIAL_ACCELERATION_STD_MPS2**2] * (3 * self._order - 6)
        self._kf.x = x[:, None]
        self._kf.P = np.diag(np.concatenate([variances, extra]))
        self._filter_changes += 1
        self._time_s = self._last_fused_s = time_s
        self._last_seen_s = {source: time_s}  # other sources' times belong to the old timeline
        self._rejections_in_a_row = 0
        self._updates_since_init = 1
        self.accepted += 1
        if reason:
            self.reinitialisations += 1
            self.last_reinit_reason = reason
            return "reinitialised"
        return "initialised"
