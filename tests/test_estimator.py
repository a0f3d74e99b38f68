"""The pose estimator: convergence, message loss, outliers, duplicates/late/reboot, real MAVLink messages."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from autonomy.estimator import (GLOBAL_POSITION_INT, LOCAL_POSITION_NED, MODELS, EstimatorConfig,
                                PoseEstimator)
from missions.geodesy import GeoPoint, LocalFrame

RATE_HZ = 10.0
POSITION_NOISE_M = 1.0
VELOCITY_NOISE_MPS = 0.2
# The filter is told the true noise of the simulated measurements.
NOISY = dict(local_position_std_m=POSITION_NOISE_M, local_velocity_std_mps=VELOCITY_NOISE_MPS)


def truth(t: float) -> tuple[np.ndarray, np.ndarray]:
    """5 m/s north for 8 s, a coordinated 90-degree turn to the east over 3 s (2.6 m/s^2), then east."""
    speed, straight_s, turn_s, down = 5.0, 8.0, 3.0, -30.0
    rate = (math.pi / 2) / turn_s
    radius = speed / rate
    if t <= straight_s:
        return np.array([speed * t, 0.0, down]), np.array([speed, 0.0, 0.0])
    if t <= straight_s + turn_s:
        a = rate * (t - straight_s)
        return (np.array([speed * straight_s + radius * math.sin(a), radius * (1 - math.cos(a)), down]),
                np.array([speed * math.cos(a), speed * math.sin(a), 0.0]))
    east = radius + speed * (t - straight_s - turn_s)
    return np.array([speed * straight_s + radius, east, down]), np.array([0.0, speed, 0.0])


def fly(est: PoseEstimator, seed: int, duration_s: float = 20.0, keep=lambda k: True, corrupt=lambda k, p: p):
    """Feed noisy LOCAL_POSITION_NED-like measurements at 10 Hz; yield (time, truth pos, truth vel, noise, outcome)."""
    rng = np.random.default_rng(seed)
    for k in range(int(duration_s * RATE_HZ) + 1):
        t = k / RATE_HZ
        position, velocity = truth(t)
        noise = rng.normal(0.0, POSITION_NOISE_M, 3)
        velocity_noise = rng.normal(0.0, VELOCITY_NOISE_MPS, 3)
        if not keep(k):
            continue
        outcome = est.update(t, corrupt(k, position + noise), velocity + velocity_noise, LOCAL_POSITION_NED)
        yield t, position, velocity, noise, velocity_noise, outcome


@pytest.mark.parametrize("model", sorted(MODELS))
def test_converges_on_noisy_data(model):
    est = PoseEstimator(EstimatorConfig(model=model, **NOISY))
    position_sq, raw_sq, velocity_sq, raw_velocity_sq = [], [], [], []
    initial_covariance = None
    for t, position, velocity, noise, velocity_noise, _ in fly(est, seed=1):
        if initial_covariance is None:
            initial_covariance = est.covariance
            assert not est.converged
        if t >= 5.0:  # after 5 s, through the turn and beyond
            position_sq.append(np.sum((est.position_ned - position) ** 2))
            raw_sq.append(np.sum(noise**2))
            velocity_sq.append(np.sum((est.velocity_ned - velocity) ** 2))
            raw_velocity_sq.append(np.sum(velocity_noise**2))
            assert np.linalg.norm(est.velocity_ned - velocity) < 1.0
            assert est.converged
    assert math.sqrt(np.mean(position_sq)) <= 0.5 * math.sqrt(np.mean(raw_sq))
    assert math.sqrt(np.mean(velocity_sq)) < math.sqrt(np.mean(raw_velocity_sq))
    position_var = np.diag(est.covariance)[:3]
    assert np.all(position_var < 0.25 * np.diag(initial_covariance)[:3])
    assert est.accepted == 201 and est.rejected_outliers == 0 and est.reinitialisations == 0


def test_bounded_error_under_20_percent_message_loss():
    drop = np.random.default_rng(7).random(201) < 0.2
    est = PoseEstimator(EstimatorConfig(**NOISY))
    errors = [np.linalg.norm(est.position_ned - position)
              for t, position, *_ in fly(est, seed=2, keep=lambda k: k == 0 or not drop[k])]
    assert 30 <= drop.sum() <= 50  # the seed really drops about a fifth
    assert est.accepted == len(errors) == 201 - drop[1:].sum()
    assert max(errors[10:]) < 2.0  # after the first second
    assert est.converged and est.reinitialisations == 0
    # predicting across a gap keeps the pose sensible at the control time
    estimate = est.predict_to(20.3)
    assert np.linalg.norm(estimate.position_ned - truth(20.3)[0]) < 2.0 and not estimate.stale


def test_rejects_an_injected_outlier():
    est = PoseEstimator(EstimatorConfig(**NOISY))
    jump = np.array([50.0, 0.0, 0.0])
    for t, position, _, _, _, outcome in fly(est, seed=3, corrupt=lambda k, p: p + jump if k == 60 else p):
        if t == 6.0:
            assert outcome == "rejected"
        if t >= 1.0:  # the first fix initialises with its own 1 m noise
            assert np.linalg.norm(est.position_ned - position) < 2.0
    assert est.rejected_outliers == 1 and est.reinitialisations == 0 and est.accepted == 200


def test_persistent_jump_is_accepted_after_consecutive_rejections():
    config = EstimatorConfig(**NOISY)
    est = PoseEstimator(config)
    jump = np.array([50.0, 0.0, 0.0])
    outcomes = {t: outcome for t, *_, outcome in fly(est, seed=4, corrupt=lambda k, p: p + jump if k >= 60 else p)}
    n = config.max_consecutive_rejections
    assert [outcomes[round(6.0 + i / RATE_HZ, 1)] for i in range(n + 1)] == ["rejected"] * n + ["reinitialised"]
    assert est.rejected_outliers == n and est.reinitialisations == 1
    assert "outliers in a row" in est.last_reinit_reason
    assert np.linalg.norm(est.position_ned - (truth(20.0)[0] + jump)) < 2.0 and est.converged


def test_duplicates_late_messages_and_tolerance():
    est = PoseEstimator()
    for k in range(20):
        assert est.update(k / 10, (k / 2, 0, 0), (5, 0, 0), LOCAL_POSITION_NED) in ("initialised", "accepted")
    before = est.position_ned
    assert est.update(1.9, (99, 0, 0), (5, 0, 0), LOCAL_POSITION_NED) == "duplicate"
    assert est.update(1.5, (7.5, 0, 0), (5, 0, 0), LOCAL_POSITION_NED) == "stale"
    assert est.ignored_duplicates == 1 and est.ignored_stale == 1
    np.testing.assert_array_equal(est.position_ned, before)
    # another source stamped a few ms earlier is within the tolerance and fused
    assert est.update(1.89, (9.45, 0, 0), (5, 0, 0), GLOBAL_POSITION_INT) == "accepted"
    assert est.time_s == 1.9 and est.accepted == 21
    assert est.update(0.1, (1, 2, 3), (0, 0, 0), LOCAL_POSITION_NED) == "stale"  # 1.8 s back: late, not a reboot
    assert est.reinitialisations == 0
    assert est.update(float("nan"), (1, 2, 3), (0, 0, 0), LOCAL_POSITION_NED) == "invalid"


def local_msg(time_boot_ms: int, position, velocity) -> mavlink.MAVLink_local_position_ned_message:
    return mavlink.MAVLink_local_position_ned_message(time_boot_ms, *map(float, position), *map(float, velocity))


def test_time_boot_ms_wrap_and_reboot_reinitialise():
    est = PoseEstimator()
    wrap_ms = 2**32
    for time_ms in range(wrap_ms - 1000, wrap_ms, 100):
        est.update_local_position_ned(local_msg(time_ms, (10, 0, -5), (0, 0, 0)))
    assert est.update_local_position_ned(local_msg(50, (10, 0, -5), (0, 0, 0))) == "reinitialised"
    assert est.reinitialisations == 1 and "went back" in est.last_reinit_reason
    for time_ms in range(150, 100_000, 100):
        est.update_local_position_ned(local_msg(time_ms, (10, 0, -5), (0, 0, 0)))
    assert est.update_local_position_ned(local_msg(1000, (-3, 4, 0), (0, 0, 0))) == "reinitialised"  # reboot
    np.testing.assert_allclose(est.position_ned, [-3, 4, 0])
    assert est.reinitialisations == 2 and not est.converged and est.ignored_stale == 0
    # a long silence re-initialises too, and the estimate before it is flagged stale
    assert est.predict_to(3.5).stale and not est.predict_to(1.5).stale
    assert est.update_local_position_ned(local_msg(4000, (0, 0, 0), (0, 0, 0))) == "reinitialised"
    assert est.reinitialisations == 3


def wire(msg, mav=mavlink.MAVLink(None)):
    """Pack and decode, so the estimator sees exactly what a link would deliver."""
    return mav.decode(bytearray(msg.pack(mav)))


def test_real_pymavlink_messages_global_path_agrees_with_local_path():
    home = GeoPoint(47.397742, 8.545594, 488.0)
    frame = LocalFrame(home)
    local_est, global_est = PoseEstimator(), PoseEstimator(home=home)
    rng = np.random.default_rng(5)
    for k in range(150):
        time_ms = 10_000 + 100 * k
        position, velocity = truth(k / RATE_HZ)
        position = position + rng.normal(0.0, 0.3, 3)
        velocity = velocity + rng.normal(0.0, 0.05, 3)
        lat, lon, alt = frame.to_geodetic(*position)
        global_msg = mavlink.MAVLink_global_position_int_message(
            time_ms, round(lat * 1e7), round(lon * 1e7), round(alt * 1000), round(-position[2] * 1000),
            *(round(v * 100) for v in velocity), 0)
        assert local_est.update_local_position_ned(wire(local_msg(time_ms, position, velocity))) != "rejected"
        assert global_est.update_global_position_int(wire(global_msg)) != "rejected"
        # agreement within the conversion error (1e-7 deg ~ 1 cm, 1 mm, 1 cm/s rounding) and the different R
        assert np.linalg.norm(local_est.position_ned - global_est.position_ned) < 0.1
        assert np.linalg.norm(local_est.velocity_ned - global_est.velocity_ned) < 0.05
    assert local_est.accepted == global_est.accepted == 150
    np.testing.assert_allclose(global_est.predict_to(25.0).position_ned, local_est.predict_to(25.0).position_ned,
                               atol=0.1)
    with pytest.raises(ValueError, match="home"):
        PoseEstimator().update_global_position_int(wire(global_msg))


@pytest.mark.parametrize("field, value", [
    ("model", "kalman"), ("model", None), ("process_noise_psd", 0.0), ("process_noise_psd", float("nan")),
    ("local_position_std_m", -1.0), ("global_velocity_std_mps", "0.1"), ("innovation_gate_chi2", 0),
    ("max_consecutive_rejections", 0), ("converged_min_updates", 2.5), ("converged_min_updates", True),
    ("late_tolerance_s", -0.01), ("late_tolerance_s", 5.0), ("max_message_age_s", math.inf),
])
def test_bad_config_values_name_the_field(field, value):
    with pytest.raises(ValueError, match=f"EstimatorConfig.{field} must be .*try the default"):
        EstimatorConfig(**{field: value})


@pytest.mark.parametrize("model", sorted(MODELS))
def test_the_written_out_transition_is_filterpys_to_the_bit(model):
    """The filter's F and Q, written out for speed, are exactly np.kron's and filterpy's
    Q_continuous_white_noise's, for any step length."""
    from filterpy.common import Q_continuous_white_noise

    estimator = PoseEstimator(EstimatorConfig(model=model))
    order = MODELS[model]
    for dt in [0.0, 0.004, 0.02, 0.1, 0.7311, 1.0, 2.5]:
        F, Q = estimator._transition(dt)
        one_axis = np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])[:order, :order]
        assert F.tobytes() == np.kron(one_axis, np.eye(3)).tobytes()
        expected = Q_continuous_white_noise(order, dt, estimator.config.process_noise_psd, block_size=3,
                                            order_by_dim=False)
        assert Q.tobytes() == expected.tobytes()
