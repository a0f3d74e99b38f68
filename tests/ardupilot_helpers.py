"""What the tests of the ArduPilot Copter personality share (tests/test_ardupilot_*.py, test_autopilot_fences.py):
command results and frames, a copter on the ground or airborne in GUIDED, its status texts and the time it flies.
Not a test module (pytest does not collect it)."""
from __future__ import annotations

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.ardupilot.modes import CopterMode
from sitl_bridge.scripted_flight import LockstepPilot
from sitl_bridge.vehicle import VehicleConfig


ACCEPTED, FAILED, DENIED = mavlink.MAV_RESULT_ACCEPTED, mavlink.MAV_RESULT_FAILED, mavlink.MAV_RESULT_DENIED
ARM, TAKEOFF = mavlink.MAV_CMD_COMPONENT_ARM_DISARM, mavlink.MAV_CMD_NAV_TAKEOFF
LOCAL_NED, BODY_NED = mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_NED
VELOCITY, POSITION = 3527, 3576


def copter(params: dict | None = None, seed: int = 3, **config) -> LockstepPilot:
    pilot = LockstepPilot.create(VehicleConfig(autopilot="ardupilot", seed=seed, params=params or {}, **config))
    pilot.wait_message("HEARTBEAT", 2.0)
    return pilot


def texts(pilot: LockstepPilot, since: int = 0) -> list[str]:
    return [m.text for m in pilot.received[since:] if m.get_type() == "STATUSTEXT"]


def last(pilot: LockstepPilot, msg_type: str):
    return next(m for m in reversed(pilot.received) if m.get_type() == msg_type)


def fly(pilot: LockstepPilot, seconds: float) -> None:
    end = pilot.vehicle.time_s + seconds
    pilot.wait_for(lambda: pilot.vehicle.time_s >= end - 1e-9, seconds + 1, "time")


def airborne(params: dict | None = None, alt_m: float = 10.0, **config) -> LockstepPilot:
    pilot = copter(params, **config)
    assert pilot.set_mode(CopterMode.GUIDED) == ACCEPTED
    assert pilot.command(ARM, 1) == ACCEPTED
    assert pilot.command(TAKEOFF, 0, 0, 0, 0, 0, 0, alt_m) == ACCEPTED
    pilot.wait_for(lambda: not pilot.vehicle.autopilot.taking_off and not pilot.vehicle.state.on_ground, 30,
                   "takeoff")
    return pilot
