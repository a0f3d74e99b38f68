"""What the multirotor dynamics' tests share (tests/test_dynamics_*.py): the default parameters, calm and gusty
wind, a vehicle in the air, stepping with a command held, and comparing states. Not a test module (pytest does not
collect it)."""
from __future__ import annotations

import math

import pytest

from sitl_bridge.dynamics import step
from sitl_bridge.multirotor import MultirotorParams, VehicleState
from sitl_bridge.wind import Wind


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
