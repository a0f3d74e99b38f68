"""Tests for the multirotor dynamics: step-size exactness, limits, ground contact, wind, battery, attitude,
and the batch API (N airborne vehicles with numpy) agreeing with the scalar step."""
from __future__ import annotations

import math
import random
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sitl_bridge.dynamics import (
    BatchState,
    attitude,
    clamp_command,
    ground_velocity,
    power_w,
    step,
    step_batch,
    velocity_toward,
)
from sitl_bridge.multirotor import HOVER, MultirotorParams, VehicleState, VelocityCommand
from sitl_bridge.wind import Wind, gust_drift

PARAMS = MultirotorParams()
CALM = Wind()
GUSTY = Wind(north_mps=4.0, east_mps=-2.0, gust_mps=3.0, seed=7)
TOL = 1e-9


def airborne(down_m: float = -20.0, **kwargs) -> VehicleState:
    """A vehicle in the air (default: hovering at 20 m, time 3 s so gusts are mid-cycle)."""
    return VehicleState(time_s=kwargs.pop("time_s", 3.0), down_m=down_m, on_ground=False, **kwargs)


def run(state, cmd, durations, wind=CALM, params=PARAMS, armed=True) -> VehicleState:
    """Step through consecutive durations with the command held."""
    for dt in durations:
        state = step(state, cmd, params, wind, dt, armed)
    return state


def assert_states_close(a: VehicleState, b: VehicleState, tol: float = TOL) -> None:
    """Every field equal to ``tol`` (yaw compared as an angle)."""
    for name in ("time_s", "north_m", "east_m", "down_m", "vn_mps", "ve_mps", "vd_mps",
                 "an_mps2", "ae_mps2", "ad_mps2", "battery_wh"):
        assert getattr(a, name) == pytest.approx(getattr(b, name), abs=tol), name
    assert abs(math.remainder(a.yaw_rad - b.yaw_rad, 2 * math.pi)) < tol
    assert a.on_ground == b.on_ground


def splits(total: float) -> list[list[float]]:
    """Several ways of cutting ``total`` seconds into steps, including uneven ones."""
    rng = random.Random(1)
    cuts = sorted(rng.uniform(0.0, total) for _ in range(13))
    uneven = [b - a for a, b in zip([0.0, *cuts], [*cuts, total])]
    return [[total / 100] * 100, [total / 7] * 7, [total / 3] * 3, uneven]


# One big step == many small steps --------------------------------------------------------------
SCENARIOS = {
    # Large velocity change: phase 1 (acceleration-limited) then phase 2, both axes.
    "accel_limited": (airborne(vn_mps=-8.0, vd_mps=1.0), VelocityCommand(10.0, 6.0, -3.0, yaw_rate_rad_s=0.7),
                      CALM, 4.0),
    # Small change: only the exponential phase.
    "exponential_only": (airborne(vn_mps=1.0), VelocityCommand(2.0, -0.5, 0.3), CALM, 2.0),
    "gusts_and_yaw": (airborne(ve_mps=3.0), VelocityCommand(-7.0, 2.0, 0.0, yaw_rad=2.5), GUSTY, 6.0),
    "landing": (airborne(down_m=-2.0, vn_mps=4.0, vd_mps=0.5), VelocityCommand(5.0, 0.0, 1.5), GUSTY, 5.0),
    "liftoff": (VehicleState(time_s=1.0), VelocityCommand(3.0, 1.0, -2.5, yaw_rad=-1.0), GUSTY, 3.0),
    # Braking a fast descent just above the ground with a climb command: touches down, lifts off again.
    "touch_and_go": (airborne(down_m=-0.2, vd_mps=1.5), VelocityCommand(0.0, 2.0, -3.0), CALM, 2.0),
    "resting": (VehicleState(time_s=2.0, yaw_rad=1.0), VelocityCommand(5.0, 5.0, 1.0, yaw_rate_rad_s=1.0),
                GUSTY, 3.0),
    "disarmed_fall": (airborne(down_m=-12.0, vn_mps=3.0, vd_mps=-1.0), HOVER, GUSTY, 3.0),
}


@pytest.mark.parametrize("name", SCENARIOS)
def test_one_big_step_equals_many_small_steps(name):
    state, cmd, wind, total = SCENARIOS[name]
    armed = name != "disarmed_fall"
    big = step(state, cmd, PARAMS, wind, total, armed)
    for durations in splits(total):
        assert_states_close(run(state, cmd, durations, wind, armed=armed), big)


def test_scenarios_exercise_what_they_claim():
    """Guard against the exactness scenarios silently testing something easier."""
    land = SCENARIOS["landing"]
    assert step(land[0], land[1], PARAMS, land[2], land[3]).on_ground
    fall = SCENARIOS["disarmed_fall"]
    assert step(fall[0], fall[1], PARAMS, fall[2], fall[3], armed=False).on_ground
    state, cmd, wind, _ = SCENARIOS["touch_and_go"]
    fine = [state := step(state, cmd, PARAMS, wind, 0.001) for _ in range(2000)]
    assert max(s.down_m for s in fine) > -1e-3  # it reached the ground...
    assert fine[-1].down_m < -1.0 and not fine[-1].on_ground  # ...and climbed away again


@settings(max_examples=60, deadline=None)
@given(
    vel=st.tuples(*[st.floats(-15.0, 15.0)] * 3),
    cmd=st.tuples(*[st.floats(-15.0, 15.0)] * 3),
    down=st.floats(-30.0, 0.0),
    total=st.floats(0.05, 5.0),
    cut=st.floats(0.01, 0.99),
)
def test_exactness_property(vel, cmd, down, total, cut):
    state = airborne(down_m=down, vn_mps=vel[0], ve_mps=vel[1], vd_mps=vel[2])
    command = VelocityCommand(*cmd)
    big = step(state, command, PARAMS, GUSTY, total)
    assert_states_close(run(state, command, [total * cut, total * (1 - cut)], GUSTY), big, tol=1e-8)


# Velocity tracking and limits -------------------------------------------------------------------
def test_steady_state_reaches_commanded_velocity():
    state = run(airborne(down_m=-50.0), VelocityCommand(6.0, -4.0, -1.0), [0.5] * 30, GUSTY)
    assert (state.vn_mps, state.ve_mps, state.vd_mps) == pytest.approx((6.0, -4.0, -1.0), abs=1e-6)
    assert (state.an_mps2, state.ae_mps2, state.ad_mps2) == pytest.approx((0.0, 0.0, 0.0), abs=1e-5)


def test_first_order_response_without_saturation():
    """Below the acceleration limit the response is exactly 1 - exp(-t / tau)."""
    state = step(airborne(), VelocityCommand(1.0, 0.0, 0.0), PARAMS, CALM, 0.5)
    assert state.vn_mps == pytest.approx(1.0 - math.exp(-1.0), rel=1e-12)


def test_speed_and_acceleration_limits_never_exceeded():
    rng = random.Random(3)
    dt = 0.01
    state = airborne(down_m=-500.0)
    top_speed = top_accel = 0.0
    for _ in range(40):  # 40 random commands, 1.5 s each, many far beyond the limits
        cmd = VelocityCommand(rng.uniform(-30, 30), rng.uniform(-30, 30), rng.uniform(-8, 8))
        for _ in range(150):
            nxt = step(state, cmd, PARAMS, CALM, dt)
            accel_xy = math.hypot(nxt.vn_mps - state.vn_mps, nxt.ve_mps - state.ve_mps) / dt
            assert accel_xy <= PARAMS.max_accel_xy_mps2 * (1 + 1e-9)
            assert abs(nxt.vd_mps - state.vd_mps) / dt <= PARAMS.max_accel_z_mps2 * (1 + 1e-9)
            assert math.hypot(nxt.an_mps2, nxt.ae_mps2) <= PARAMS.max_accel_xy_mps2 + 1e-9
            assert math.hypot(nxt.vn_mps, nxt.ve_mps) <= PARAMS.max_speed_xy_mps + 1e-9
            assert -PARAMS.max_speed_up_mps - 1e-9 <= nxt.vd_mps <= PARAMS.max_speed_down_mps + 1e-9
            top_speed = max(top_speed, math.hypot(nxt.vn_mps, nxt.ve_mps))
            top_accel = max(top_accel, accel_xy)
            state = nxt
    # The limits were actually reached, not just respected.
    assert top_speed > 0.99 * PARAMS.max_speed_xy_mps
    assert top_accel > 0.99 * PARAMS.max_accel_xy_mps2


def test_clamp_command_limits():
    c = clamp_command(VelocityCommand(30.0, 40.0, -10.0, yaw_rate_rad_s=5.0), PARAMS)
    assert math.hypot(c.north_mps, c.east_mps) == pytest.approx(PARAMS.max_speed_xy_mps)
    assert c.north_mps / c.east_mps == pytest.approx(30.0 / 40.0)  # direction kept
    assert c.down_mps == -PARAMS.max_speed_up_mps
    assert c.yaw_rate_rad_s == PARAMS.max_yaw_rate_rad_s
    c = clamp_command(VelocityCommand(1.0, -2.0, 10.0, yaw_rate_rad_s=-5.0), PARAMS)
    assert (c.north_mps, c.east_mps, c.down_mps) == (1.0, -2.0, PARAMS.max_speed_down_mps)
    assert c.yaw_rate_rad_s == -PARAMS.max_yaw_rate_rad_s
    wrapped = clamp_command(VelocityCommand(yaw_rad=3 * math.pi / 2), PARAMS).yaw_rad
    assert wrapped == pytest.approx(-math.pi / 2)


def test_clamp_command_non_finite_becomes_safe():
    nan, inf = math.nan, math.inf
    c = clamp_command(VelocityCommand(nan, inf, nan, yaw_rad=nan), PARAMS)
    assert (c.north_mps, c.east_mps, c.down_mps) == (0.0, 0.0, 0.0)
    assert c.yaw_rad is None  # hold heading
    c = clamp_command(VelocityCommand(3.0, nan, yaw_rate_rad_s=nan), PARAMS)
    assert c == VelocityCommand(3.0, 0.0, 0.0, None, 0.0)
    state = step(airborne(vn_mps=2.0), VelocityCommand(nan, nan, nan), PARAMS, CALM, 20.0)
    assert all(math.isfinite(getattr(state, f)) for f in ("north_m", "east_m", "down_m", "vn_mps"))
    assert state.vn_mps == pytest.approx(0.0, abs=1e-12)


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


# Yaw --------------------------------------------------------------------------------------------
def test_yaw_turns_shortest_way_at_max_rate_then_holds():
    rate = PARAMS.max_yaw_rate_rad_s
    start = airborne(yaw_rad=math.radians(170.0))
    cmd = VelocityCommand(yaw_rad=math.radians(-170.0))  # 20 degrees away through 180
    s = step(start, cmd, PARAMS, CALM, 0.1)
    assert s.yaw_rad == pytest.approx(math.radians(170.0) + 0.1 * rate)
    s = step(s, cmd, PARAMS, CALM, 0.2)  # crosses +-180
    assert s.yaw_rad == pytest.approx(math.radians(170.0) + 0.3 * rate - 2 * math.pi)
    assert -math.pi < s.yaw_rad <= math.pi
    s = step(s, cmd, PARAMS, CALM, 5.0)
    assert s.yaw_rad == pytest.approx(math.radians(-170.0))
    s = step(s, HOVER, PARAMS, CALM, 5.0)  # both None: hold
    assert s.yaw_rad == pytest.approx(math.radians(-170.0))


def test_yaw_rate_command_is_clamped():
    s = step(airborne(), VelocityCommand(yaw_rate_rad_s=-10.0), PARAMS, CALM, 1.0)
    assert s.yaw_rad == pytest.approx(-PARAMS.max_yaw_rate_rad_s)


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


# Attitude ---------------------------------------------------------------------------------------
def test_attitude_forward_acceleration_pitches_nose_down():
    roll, pitch, yaw = attitude(airborne(an_mps2=3.0), PARAMS, CALM)
    assert pitch == pytest.approx(-math.atan2(3.0, 9.80665)) and roll == pytest.approx(0.0)
    # Facing east, an eastward acceleration is forward; a southward one is to the right.
    _, pitch_e, _ = attitude(airborne(ae_mps2=3.0, yaw_rad=math.pi / 2), PARAMS, CALM)
    roll_s, _, _ = attitude(airborne(an_mps2=-3.0, yaw_rad=math.pi / 2), PARAMS, CALM)
    assert pitch_e < -0.2 and roll_s > 0.2


def test_attitude_leans_into_the_wind_and_is_level_on_ground():
    # Air moving south (wind from the north): hovering means leaning north, i.e. nose down at yaw 0.
    _, pitch, _ = attitude(airborne(), PARAMS, Wind(north_mps=-8.0))
    assert pitch < -math.radians(5.0)
    # Cruising at constant speed in still air also needs a forward tilt against drag.
    assert attitude(airborne(vn_mps=12.0), PARAMS, CALM)[1] < -math.radians(10.0)
    assert attitude(VehicleState(yaw_rad=1.2), PARAMS, Wind(north_mps=-8.0)) == (0.0, 0.0, 1.2)


# Position controller ----------------------------------------------------------------------------
@pytest.mark.parametrize("wind", [CALM, GUSTY], ids=["calm", "gusty"])
def test_velocity_toward_reaches_target_without_big_overshoot(wind):
    target = (60.0, -25.0, -15.0)
    state = VehicleState()
    start = (0.0, 0.0)
    direction = (target[0] / math.hypot(*target[:2]), target[1] / math.hypot(*target[:2]))
    max_along = -math.inf
    for _ in range(6000):  # 60 s at 100 Hz
        cmd = velocity_toward(state, *target, PARAMS, speed_xy_mps=10.0)
        state = step(state, cmd, PARAMS, wind, 0.01)
        along = (state.north_m - start[0]) * direction[0] + (state.east_m - start[1]) * direction[1]
        max_along = max(max_along, along)
        if state.time_s > 50.0:  # settled: gusts leaking through the P loop are the only error left
            miss = math.dist((state.north_m, state.east_m, state.down_m), target)
            # In calm air the P loop settles exactly; gusts leak through it (~1 m/s here at gain 1/s).
            assert miss < (0.1 if wind is CALM else 2.0)
    overshoot = max_along - math.hypot(*target[:2])  # distance past the target along the leg
    assert overshoot < (0.05 if wind is CALM else 2.0)
    assert not state.on_ground


def test_velocity_toward_respects_requested_speeds():
    state = airborne()
    cmd = velocity_toward(state, 100.0, 0.0, -100.0, PARAMS, speed_xy_mps=4.0, speed_z_mps=1.0)
    assert (cmd.north_mps, cmd.east_mps, cmd.down_mps) == pytest.approx((4.0, 0.0, -1.0))
    assert velocity_toward(state, 0.0, 0.0, -20.0, PARAMS, speed_xy_mps=4.0) == VelocityCommand(0.0, 0.0, 0.0)


# Batch API: N airborne vehicles at once, the same physics as step() ----------------------------------
def random_fleet(rng: np.random.Generator, n: int) -> tuple[list[VehicleState], np.ndarray]:
    """N airborne vehicles well above the ground, many far from their commands (acceleration-limited),
    some beyond the speed limits or nearly out of battery; and each one's own clock (gust phase)."""
    times = rng.uniform(0.0, 500.0, n)
    states = [airborne(time_s=float(t), down_m=rng.uniform(-200.0, -60.0), north_m=rng.uniform(-100.0, 100.0),
                       east_m=rng.uniform(-100.0, 100.0), vn_mps=rng.uniform(-15.0, 15.0),
                       ve_mps=rng.uniform(-15.0, 15.0), vd_mps=rng.uniform(-4.0, 4.0),
                       yaw_rad=rng.uniform(-math.pi, math.pi), battery_wh=rng.choice([90.0, 30.0, 0.01]))
                   for t in times]
    return states, times


def random_commands(rng: np.random.Generator, n: int, scale: float) -> np.ndarray:
    """(n, 3) NED velocity commands up to ``scale`` m/s, a few of them non-finite."""
    cmd = rng.uniform(-scale, scale, (n, 3))
    cmd[rng.random((n, 3)) < 0.03] = rng.choice([math.nan, math.inf, -math.inf])
    return cmd


def assert_batch_matches(batch: BatchState, states: list[VehicleState], tol: float) -> None:
    for i, expected in enumerate(states):
        got = batch.state(i, expected.time_s)
        for name in ("north_m", "east_m", "down_m", "vn_mps", "ve_mps", "vd_mps", "battery_wh"):
            assert getattr(got, name) == pytest.approx(getattr(expected, name), abs=tol), (i, name)
        assert abs(math.remainder(got.yaw_rad - expected.yaw_rad, 2 * math.pi)) < tol, (i, "yaw_rad")
        assert -math.pi < got.yaw_rad <= math.pi


@pytest.mark.parametrize("yaw_mode", ["hold", "rate", "target"])
@pytest.mark.parametrize("wind", [CALM, GUSTY], ids=["calm", "gusty"])
@pytest.mark.parametrize("dt", [1.0, 0.37, 0.01])
def test_step_batch_equals_scalar_steps(dt, wind, yaw_mode):
    n = 64
    rng = np.random.default_rng(int(dt * 100) + 7 * len(yaw_mode) + (wind is GUSTY))
    states, times = random_fleet(rng, n)
    cmd = random_commands(rng, n, 20.0)
    rates = np.where(rng.random(n) < 0.1, math.nan, rng.uniform(-3.0, 3.0, n))  # beyond the limit too
    targets = np.where(rng.random(n) < 0.2, math.nan, rng.uniform(-10.0, 10.0, n))  # NaN: use the rate
    yaw_kwargs = {"hold": {}, "rate": {"cmd_yaw_rate_rad_s": rates},
                  "target": {"cmd_yaw_rad": targets, "cmd_yaw_rate_rad_s": rates}}[yaw_mode]
    batch = step_batch(BatchState.from_states(states), cmd[:, 0], cmd[:, 1], cmd[:, 2], PARAMS, wind,
                       times, dt, **yaw_kwargs)
    expected = []
    for i, state in enumerate(states):
        command = VelocityCommand(*cmd[i], yaw_rad=float(targets[i]) if yaw_mode == "target" else None,
                                  yaw_rate_rad_s=float(rates[i]) if yaw_mode != "hold" else None)
        expected.append(step(state, command, PARAMS, wind, dt))
    assert_batch_matches(batch, expected, tol=1e-12)
    # The acceleration limits were active for many vehicles (phase 1 of the velocity tracking).
    knee = PARAMS.max_accel_xy_mps2 * PARAMS.velocity_time_constant_s
    clamped = [clamp_command(VelocityCommand(*c), PARAMS) for c in cmd]
    far = sum(math.hypot(c.north_mps - s.vn_mps, c.east_mps - s.ve_mps) > 2 * knee for c, s in zip(clamped, states))
    assert far > n // 4


def test_step_batch_one_big_step_equals_many_small_steps():
    n, total = 48, 3.0
    rng = np.random.default_rng(11)
    states, times = random_fleet(rng, n)
    cmd = random_commands(rng, n, 20.0)
    rates = rng.uniform(-2.0, 2.0, n)  # turns through +-pi within the 3 s
    start = BatchState.from_states(states)
    big = step_batch(start, *cmd.T, PARAMS, GUSTY, times, total, cmd_yaw_rate_rad_s=rates)
    for durations in splits(total):
        fleet, clock = start.copy(), times.copy()
        for dt in durations:
            step_batch(fleet, *cmd.T, PARAMS, GUSTY, clock, dt, out=fleet, cmd_yaw_rate_rad_s=rates)  # in place
            clock += dt
        assert_batch_matches(fleet, [big.state(i, times[i] + total) for i in range(n)], tol=TOL)
    assert np.array_equal(start.north_m, np.array([s.north_m for s in states]))  # input left alone


def test_batch_state_round_trip_and_validation():
    states, _ = random_fleet(np.random.default_rng(2), 5)
    batch = BatchState.from_states(states)
    assert batch.north_m.dtype == np.float64 and batch.north_m.shape == (5,)
    for i, state in enumerate(states):  # accelerations are not kept by the batch
        assert batch.state(i, state.time_s) == replace(state, an_mps2=0.0, ae_mps2=0.0, ad_mps2=0.0)
    with pytest.raises(ValueError, match="on the ground"):
        BatchState.from_states([states[0], VehicleState()])
    with pytest.raises(ValueError, match="dt_s"):
        step_batch(batch, 0.0, 0.0, 0.0, PARAMS, CALM, 0.0, -1.0)


def test_step_batch_rejects_ground_contact_exactly_like_step():
    def fleet(down_m, vd_mps):
        return BatchState.from_states([airborne(down_m=-50.0), airborne(down_m=down_m, vd_mps=vd_mps)])

    # Ends below the ground.
    with pytest.raises(ValueError, match="vehicle 1 .*touch the ground"):
        step_batch(fleet(-0.5, 1.5), 0.0, 0.0, np.array([0.0, 1.5]), PARAMS, CALM, 3.0, 1.0)
    # Braking a descent close to the ground with a climb: ends in the air but touched down on the way.
    cmd_down = np.array([0.0, -3.0])
    assert step(airborne(down_m=-0.2, vd_mps=1.5), VelocityCommand(0.0, 0.0, -3.0), PARAMS, CALM, 2.0).down_m < -1.0
    with pytest.raises(ValueError, match="vehicle 1"):
        step_batch(fleet(-0.2, 1.5), 0.0, 0.0, cmd_down, PARAMS, CALM, 3.0, 2.0)
    # Resting at ground level, or below it, is not airborne either.
    with pytest.raises(ValueError, match="vehicle 1"):
        step_batch(fleet(0.0, 0.0), 0.0, 0.0, 0.0, PARAMS, CALM, 3.0, 0.01)
    with pytest.raises(ValueError, match="vehicle 1"):
        step_batch(fleet(0.5, 0.0), 0.0, 0.0, cmd_down, PARAMS, CALM, 3.0, 0.01)
    # Close to the ground but braking in time: the cheap bound flags it, the exact check lets it fly.
    close = airborne(down_m=-1.0, vd_mps=1.5)
    assert close.down_m + close.vd_mps * 1.0 >= 0.0
    batch = step_batch(BatchState.from_states([close]), 2.0, 0.0, 0.0, PARAMS, GUSTY, 3.0, 1.0)
    expected = step(close, VelocityCommand(2.0, 0.0, 0.0), PARAMS, GUSTY, 1.0)
    assert not expected.on_ground and expected.down_m > -0.5
    assert_batch_matches(batch, [expected], tol=1e-12)
