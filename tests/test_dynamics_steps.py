"""Tests for the multirotor dynamics' stepping: step-size exactness (one big step equals many small steps, by
scenario and as a property), and the batch API (N airborne vehicles with numpy) agreeing with the scalar step."""
from __future__ import annotations

import math
import random
from dataclasses import replace

import numpy as np
import pytest
from dynamics_helpers import CALM, GUSTY, PARAMS, TOL, airborne, assert_states_close, run
from hypothesis import given, settings
from hypothesis import strategies as st

from sitl_bridge.dynamics import BatchState, clamp_command, step, step_batch
from sitl_bridge.multirotor import HOVER, VehicleState, VelocityCommand


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
