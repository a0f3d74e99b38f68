"""Tests for the multirotor dynamics' surroundings: ground contact (lift-off, touchdown, disarmed), the battery,
wind and its gusts, and invalid parameters."""
from __future__ import annotations

import math

import pytest
from dynamics_helpers import CALM, GUSTY, PARAMS, airborne, run

from sitl_bridge.dynamics import ground_velocity, power_w, step
from sitl_bridge.multirotor import HOVER, MultirotorParams, VehicleState, VelocityCommand
from sitl_bridge.wind import Wind, gust_drift


# Ground contact ---------------------------------------------------------------------------------
def test_stays_on_ground_with_level_or_descend_command():
    start = VehicleState(north_m=5.0, east_m=-3.0, yaw_rad=0.4)
    for cmd in (HOVER, VelocityCommand(8.0, 8.0, 1.0, yaw_rate_rad_s=1.0)):
        state = run(start, cmd, [0.01] * 200, GUSTY)
        assert state.on_ground
        assert (state.north_m, state.east_m, state.down_m) == (5.0, -3.0, 0.0)  # no sliding, no gust drift
        assert (state.vn_mps, state.ve_mps, state.vd_mps) == (0.0, 0.0, 0.0)
        assert state.yaw_rad == 0.4  # no yawing on the ground
        assert ground_velocity(state, PARAMS, GUSTY) == (0.0, 0.0, 0.0)
        assert state.battery_wh == pytest.approx(start.battery_wh - PARAMS.idle_power_w * 2.0 / 3600)


def test_lifts_off_with_climb_command():
    state = step(VehicleState(), VelocityCommand(0.0, 0.0, -2.0), PARAMS, CALM, 1.0)
    assert not state.on_ground
    # From rest, below the acceleration limit: vd = -2 (1 - exp(-t/tau)), integrated.
    tau = PARAMS.velocity_time_constant_s
    assert state.down_m == pytest.approx(-2.0 * (1.0 - tau * (1.0 - math.exp(-1.0 / tau))), rel=1e-12)
    assert state.vd_mps < 0.0


def test_touchdown_lands_exactly_at_zero_and_stops():
    start = airborne(down_m=-5.0, time_s=0.0)
    cmd = VelocityCommand(2.0, 0.0, 1.5)
    tau = PARAMS.velocity_time_constant_s  # a_z * tau = 2 > 1.5: pure exponential response

    def down(t):
        return -5.0 + 1.5 * t - 1.5 * tau * (1.0 - math.exp(-t / tau))

    lo, hi = 0.0, 10.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if down(mid) < 0 else (lo, mid)
    t_touch = lo
    before = step(start, cmd, PARAMS, CALM, t_touch - 1e-6)
    assert not before.on_ground and -2e-6 < before.down_m < 0.0
    after = step(start, cmd, PARAMS, CALM, t_touch + 1e-6)
    assert after.on_ground and after.down_m == 0.0
    assert (after.vn_mps, after.ve_mps, after.vd_mps) == (0.0, 0.0, 0.0)
    # Resting afterwards: the horizontal command does not slide it along.
    later = step(after, cmd, PARAMS, CALM, 5.0)
    assert (later.north_m, later.down_m, later.on_ground) == (after.north_m, 0.0, True)
    assert after.north_m == pytest.approx(before.north_m, abs=1e-4)


def test_down_never_positive():
    state = airborne(down_m=-3.0)
    for _ in range(500):
        state = step(state, VelocityCommand(3.0, 0.0, 5.0), PARAMS, GUSTY, 0.037)
        assert state.down_m <= 0.0


def test_disarmed_is_inert_on_ground_and_falls_in_air():
    start = VehicleState(north_m=1.0, battery_wh=50.0)
    state = run(start, VelocityCommand(5.0, 0.0, -3.0), [0.1] * 10, GUSTY, armed=False)
    assert state.time_s == pytest.approx(1.0)
    assert (state.north_m, state.down_m, state.battery_wh, state.on_ground) == (1.0, 0.0, 50.0, True)
    fall = step(airborne(down_m=-4.9), HOVER, PARAMS, CALM, 0.5, armed=False)
    assert fall.down_m == pytest.approx(-4.9 + 0.5 * 9.80665 * 0.25)
    assert step(airborne(down_m=-4.9), HOVER, PARAMS, CALM, 2.0, armed=False).on_ground


# Battery ----------------------------------------------------------------------------------------
def test_battery_drains_more_flying_fast_than_hovering():
    fast_cmd = VelocityCommand(12.0, 0.0, 0.0)
    hover = step(airborne(vn_mps=12.0), HOVER, PARAMS, CALM, 60.0)
    fast = step(airborne(vn_mps=12.0), fast_cmd, PARAMS, CALM, 60.0)
    idle = step(VehicleState(), HOVER, PARAMS, CALM, 60.0)
    start = airborne().battery_wh
    assert start - fast.battery_wh > start - hover.battery_wh > start - idle.battery_wh > 0.0
    assert start - hover.battery_wh == pytest.approx(PARAMS.hover_power_w * 60.0 / 3600.0)
    fast_w = power_w(airborne(), fast_cmd, PARAMS, CALM)
    assert start - fast.battery_wh == pytest.approx(fast_w * 60.0 / 3600.0)
    assert power_w(airborne(), fast_cmd, PARAMS, CALM, armed=False) == 0.0


def test_battery_never_negative():
    state = run(airborne(battery_wh=0.05), VelocityCommand(12.0, 0.0, -3.0), [1.0] * 10)
    assert state.battery_wh == 0.0


# Wind -------------------------------------------------------------------------------------------
def test_gust_drift_is_the_leaked_integral_of_gust_velocity():
    t0, t1, n = 12.3, 19.8, 2000  # Simpson's rule, n even
    h = (t1 - t0) / n
    numeric = [0.0, 0.0]
    for i in range(n + 1):
        weight = 1 if i in (0, n) else 4 if i % 2 else 2
        for axis, g in enumerate(GUSTY.gust_velocity(t0 + i * h)[:2]):
            numeric[axis] += weight * g * h / 3 * PARAMS.gust_response
    assert gust_drift(PARAMS, GUSTY, t0, t1) == pytest.approx(tuple(numeric), abs=1e-9)
    a, b = gust_drift(PARAMS, GUSTY, t0, 15.0), gust_drift(PARAMS, GUSTY, 15.0, t1)
    assert tuple(x + y for x, y in zip(a, b)) == pytest.approx(gust_drift(PARAMS, GUSTY, t0, t1), abs=1e-12)


def test_gusts_are_deterministic_per_seed_and_sized_by_amplitude():
    times = [0.5 * i for i in range(2000)]
    same = Wind(gust_mps=3.0, seed=7)
    assert [same.gust_velocity(t) for t in times[:50]] == [GUSTY.gust_velocity(t) for t in times[:50]]
    other = Wind(gust_mps=3.0, seed=8)
    assert max(abs(other.gust_velocity(t)[0] - GUSTY.gust_velocity(t)[0]) for t in times) > 0.5
    samples = [GUSTY.gust_velocity(t) for t in times]
    rms_xy = math.sqrt(sum(g[0] ** 2 + g[1] ** 2 for g in samples) / len(samples))
    rms_z = math.sqrt(sum(g[2] ** 2 for g in samples) / len(samples))
    assert 0.6 * 3.0 < rms_xy < 1.4 * 3.0
    assert rms_z < 0.5 * rms_xy
    assert Wind().gust_velocity(4.0) == (0.0, 0.0, 0.0)


def test_steady_wind_is_rejected_and_gusts_leak_through():
    hold = run(airborne(time_s=0.0), HOVER, [0.01] * 100, Wind(north_mps=8.0))
    assert (hold.north_m, hold.east_m) == (0.0, 0.0)
    drift = step(airborne(time_s=0.0), HOVER, PARAMS, GUSTY, 1.0)
    assert (drift.north_m, drift.east_m) == pytest.approx(gust_drift(PARAMS, GUSTY, 0.0, 1.0))
    r = PARAMS.gust_response
    vn, ve, vd = ground_velocity(drift, PARAMS, GUSTY)
    gvn, gve, _ = GUSTY.gust_velocity(1.0)
    assert (vn, ve, vd) == pytest.approx((r * gvn, r * gve, 0.0))


def test_invalid_parameters_name_the_field():
    with pytest.raises(ValueError, match="max_speed_xy_mps"):
        MultirotorParams(max_speed_xy_mps=-1.0)
    with pytest.raises(ValueError, match=r"gust_response.*\[0, 1\]"):
        MultirotorParams(gust_response=1.5)
    with pytest.raises(ValueError, match="gust_mps"):
        Wind(gust_mps=math.nan)
    with pytest.raises(ValueError, match="dt_s"):
        step(airborne(), HOVER, PARAMS, CALM, -0.1)
