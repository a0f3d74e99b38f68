"""Tests for the seeded sensor models of the simulated vehicle."""

from __future__ import annotations

import dataclasses
import math
import statistics

import pytest

from sitl_bridge.sensors import GpsFix, SensorConfig, SensorSuite, wrap_pi

POSITION = (120.0, -35.0, -42.0)
VELOCITY = (3.0, -1.0, 0.5)
ATTITUDE = (0.05, -0.02, 3.13)


def run(suite: SensorSuite, rate_hz: float, duration_s: float, *, accumulate: bool = False) -> list[GpsFix]:
    """Drive ``suite`` with a constant true state; return every new GPS fix in order."""
    fixes: list[GpsFix] = []
    dt = 1.0 / rate_hz
    time_s = 0.0
    for step in range(round(duration_s * rate_hz)):
        # Either way a simulator might keep time: step * dt, or summing dt (which drifts by ulps).
        if not accumulate:
            time_s = step * dt
        count = suite.gps_fix_count
        suite.update(time_s, POSITION, VELOCITY, ATTITUDE)
        if suite.gps_fix_count != count:
            assert suite.gps is not None
            fixes.append(suite.gps)
        if accumulate:
            time_s += dt
    return fixes


def trace(seed: int) -> list[object]:
    """Every reading a suite produces over 3 s at 200 Hz."""
    suite = SensorSuite(seed=seed)
    readings: list[object] = []
    for step in range(600):
        suite.update(step / 200.0, POSITION, VELOCITY, ATTITUDE)
        readings.append((suite.gps, suite.gps_fix_count, suite.baro_alt_m, suite.attitude_rpy))
    return readings


def test_same_seed_gives_bit_identical_readings() -> None:
    assert trace(42) == trace(42)  # float equality: bit-identical, not merely close


def test_different_seeds_give_different_readings() -> None:
    assert trace(1) != trace(2)


def test_no_fix_before_first_update() -> None:
    suite = SensorSuite()
    assert suite.gps is None
    assert suite.gps_fix_count == 0


@pytest.mark.parametrize("caller_rate_hz", [200.0, 50.0])
@pytest.mark.parametrize("gps_rate_hz", [10.0, 5.0])
@pytest.mark.parametrize("accumulate", [False, True], ids=["step_times_dt", "summed_dt"])
def test_gps_fixes_arrive_at_configured_rate(
    caller_rate_hz: float, gps_rate_hz: float, accumulate: bool
) -> None:
    suite = SensorSuite(SensorConfig(gps_rate_hz=gps_rate_hz), seed=3)
    fixes = run(suite, caller_rate_hz, 10.0, accumulate=accumulate)
    assert len(fixes) == round(10.0 * gps_rate_hz)
    assert suite.gps_fix_count == len(fixes)
    # Fixes sit on the grid k / rate, whatever the caller's step (which divides the GPS period here).
    for k, fix in enumerate(fixes):
        assert fix.time_s == pytest.approx(k / gps_rate_hz, abs=1e-9)


def test_fix_timing_with_a_step_that_does_not_divide_the_gps_period() -> None:
    # At 30 Hz the first update at or after each 0.1 s grid point carries the fix.
    fixes = run(SensorSuite(seed=4), 30.0, 10.0)
    assert len(fixes) == 100
    for k, fix in enumerate(fixes):
        assert k / 10.0 - 1e-9 <= fix.time_s < k / 10.0 + 1.0 / 30.0


def test_gps_reading_is_unchanged_between_fixes() -> None:
    suite = SensorSuite(seed=5)
    suite.update(0.0, POSITION, VELOCITY, ATTITUDE)
    first = suite.gps
    suite.update(0.05, POSITION, VELOCITY, ATTITUDE)
    assert suite.gps is first and suite.gps_fix_count == 1
    suite.update(0.1, POSITION, VELOCITY, ATTITUDE)
    assert suite.gps is not first and suite.gps_fix_count == 2


def test_time_must_not_go_backwards() -> None:
    suite = SensorSuite()
    suite.update(1.0, POSITION, VELOCITY, ATTITUDE)
    with pytest.raises(ValueError, match="time_s"):
        suite.update(0.5, POSITION, VELOCITY, ATTITUDE)


def test_gps_error_statistics_match_configuration() -> None:
    # Pool many independent short runs: the bias wanders over a minute, so a single run would hold
    # too few independent bias samples to estimate its spread.
    config = SensorConfig()
    north_errors: list[float] = []
    east_errors: list[float] = []
    down_errors: list[float] = []
    velocity_errors: list[float] = []
    fixes: list[GpsFix] = []
    for seed in range(300):
        fixes += run(SensorSuite(config, seed=seed), 10.0, 2.0)
    for fix in fixes:
        north_errors.append(fix.north_m - POSITION[0])
        east_errors.append(fix.east_m - POSITION[1])
        down_errors.append(fix.down_m - POSITION[2])
        velocity_errors.append(fix.vn_mps - VELOCITY[0])
    horizontal_std = math.hypot(config.gps_horizontal_noise_m, config.gps_bias_std_m)
    vertical_std = math.hypot(config.gps_vertical_noise_m, config.gps_bias_std_m)
    assert statistics.pstdev(north_errors) == pytest.approx(horizontal_std, rel=0.2)
    assert statistics.pstdev(east_errors) == pytest.approx(horizontal_std, rel=0.2)
    assert statistics.pstdev(down_errors) == pytest.approx(vertical_std, rel=0.2)
    assert statistics.pstdev(velocity_errors) == pytest.approx(config.gps_velocity_noise_mps, rel=0.2)
    assert abs(statistics.fmean(north_errors)) < 0.2
    # The reported accuracy is the same combined std, so a Kalman filter can use it directly.
    assert all(fix.eph_m == pytest.approx(horizontal_std) for fix in fixes)
    assert all(fix.epv_m == pytest.approx(vertical_std) for fix in fixes)


def test_gps_bias_wanders_slowly() -> None:
    suite = SensorSuite(seed=6)
    bias_north: list[float] = []
    for step in range(1800 * 10):  # 30 min at the GPS rate: thirty time constants
        suite.update(step / 10.0, POSITION, VELOCITY, ATTITUDE)
        if step % 10 == 0:
            bias_north.append(suite.gps_bias_ned_m[0])
    lag_1s = statistics.correlation(bias_north[:-1], bias_north[1:])
    assert lag_1s > 0.9
    assert lag_1s == pytest.approx(math.exp(-1.0 / SensorConfig().gps_bias_time_constant_s), abs=0.02)


def test_gps_bias_keeps_its_steady_state_spread() -> None:
    # Exact Gauss-Markov discretisation: the spread across seeds is the configured std at any time,
    # whatever the caller's step.
    config = SensorConfig()
    early: list[float] = []
    late: list[float] = []
    for seed in range(400):
        suite = SensorSuite(config, seed=1000 + seed)
        suite.update(0.0, POSITION, VELOCITY, ATTITUDE)
        early.append(suite.gps_bias_ned_m[0])
        suite.update(300.0, POSITION, VELOCITY, ATTITUDE)  # one long step of five time constants
        late.append(suite.gps_bias_ned_m[0])
    assert statistics.pstdev(early) == pytest.approx(config.gps_bias_std_m, rel=0.15)
    assert statistics.pstdev(late) == pytest.approx(config.gps_bias_std_m, rel=0.15)
    assert abs(statistics.correlation(early, late)) < 0.2  # decorrelated after 5 time constants


def test_baro_error_is_bounded_and_has_the_configured_spread() -> None:
    config = SensorConfig()
    errors: list[float] = []
    for seed in range(100):
        suite = SensorSuite(config, seed=seed)
        for step in range(20 * 50):  # 20 s at 50 Hz
            suite.update(step / 50.0, POSITION, VELOCITY, ATTITUDE)
            errors.append(suite.baro_alt_m - (-POSITION[2]))  # altitude is up positive
    assert abs(statistics.fmean(errors)) < 0.1
    combined = math.hypot(config.baro_noise_m, config.baro_bias_std_m)
    assert statistics.pstdev(errors) == pytest.approx(combined, rel=0.2)
    assert max(abs(e) for e in errors) < 6 * combined


def test_attitude_noise_and_yaw_wrapping() -> None:
    suite = SensorSuite(seed=8)
    roll_errors: list[float] = []
    yaw_errors: list[float] = []
    for step in range(5000):
        suite.update(step / 200.0, POSITION, VELOCITY, (0.1, -0.2, math.pi))
        roll, _, yaw = suite.attitude_rpy
        assert -math.pi < yaw <= math.pi
        roll_errors.append(roll - 0.1)
        yaw_errors.append(wrap_pi(yaw - math.pi))
    assert statistics.pstdev(roll_errors) == pytest.approx(SensorConfig().attitude_noise_rad, rel=0.1)
    assert statistics.pstdev(yaw_errors) == pytest.approx(SensorConfig().heading_noise_rad, rel=0.1)


def test_wrap_pi_range() -> None:
    assert wrap_pi(-math.pi) == math.pi
    assert wrap_pi(math.pi) == math.pi
    assert wrap_pi(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert wrap_pi(-7.0) == pytest.approx(-7.0 + 2 * math.pi)


def test_zero_noise_reproduces_truth() -> None:
    noise_fields = [f.name for f in dataclasses.fields(SensorConfig) if f.name.endswith(("_m", "_mps", "_rad"))]
    quiet = SensorConfig(**{name: 0.0 for name in noise_fields})
    suite = SensorSuite(quiet, seed=9)
    suite.update(0.0, POSITION, VELOCITY, ATTITUDE)
    assert suite.gps is not None
    assert (suite.gps.north_m, suite.gps.east_m, suite.gps.down_m) == POSITION
    assert (suite.gps.vn_mps, suite.gps.ve_mps, suite.gps.vd_mps) == VELOCITY
    assert suite.baro_alt_m == -POSITION[2]
    assert suite.attitude_rpy == ATTITUDE


@pytest.mark.parametrize(
    ("field", "value", "wording"),
    [
        ("gps_rate_hz", 20.0, r"\[5, 10\]"),
        ("gps_rate_hz", 4.9, r"\[5, 10\]"),
        ("gps_rate_hz", math.nan, r"\[5, 10\]"),
        ("gps_horizontal_noise_m", -0.1, ">= 0"),
        ("gps_bias_std_m", math.inf, ">= 0"),
        ("baro_noise_m", "0.05", ">= 0"),
        ("gps_bias_time_constant_s", 0.0, "> 0"),
        ("baro_bias_time_constant_s", -5.0, "> 0"),
        ("heading_noise_rad", True, ">= 0"),
    ],
)
def test_config_validation_names_the_field(field: str, value: object, wording: str) -> None:
    with pytest.raises(ValueError, match=f"SensorConfig.{field} must be") as error:
        SensorConfig(**{field: value})  # type: ignore[arg-type]
    assert error.match(wording)


def test_config_accepts_the_rate_limits() -> None:
    SensorConfig(gps_rate_hz=5)
    SensorConfig(gps_rate_hz=10.0)
