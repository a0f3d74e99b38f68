"""The simulated vehicle's MAVLink system id and reboots, as PX4 and ArduPilot have them: MAV_SYS_ID /
SYSID_THISMAV set at boot is the id the vehicle speaks and answers as; a PARAM_SET of it waits for the next boot;
MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN reboots a disarmed autopilot and is refused while armed."""
from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.ardupilot.modes import CopterMode
from sitl_bridge.params import INT32, encode_bytewise
from sitl_bridge.px4.modes import FlightMode
from sitl_bridge.scripted_flight import LockstepPilot, LockstepTimeout
from sitl_bridge.vehicle import SYSTEM_ID_PARAM
from sitl_bridge.vehicle_config import VehicleConfig

REBOOT = mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN


def booted(autopilot: str, **params: float) -> LockstepPilot:
    pilot = LockstepPilot.create(VehicleConfig(seed=1, autopilot=autopilot, params=params))
    pilot.wait_for(lambda: pilot.vehicle.autopilot.gps_ok, 2.0, "GPS")
    return pilot


def heartbeat_sources(pilot: LockstepPilot, since: int) -> set[int]:
    return {m.get_srcSystem() for m in pilot.received[since:] if m.get_type() == "HEARTBEAT"}


def command_to(pilot: LockstepPilot, system: int, command: int, *params: float) -> int | None:
    """COMMAND_LONG to ``system``'s autopilot; the ACK's result, or None when no ACK came within a second."""
    pilot.mav.command_long_send(system, 1, command, 0, *params, *[0.0] * (7 - len(params)))
    try:
        ack = pilot.wait_message("COMMAND_ACK", 1.0, lambda m: m.command == command)
    except LockstepTimeout:
        return None
    assert ack.get_srcSystem() == pilot.vehicle.system_id
    return ack.result


def set_system_id(pilot: LockstepPilot, autopilot: str, value: int) -> float:
    """PARAM_SET of the system-id parameter as each autopilot encodes an integer (PX4 bytewise, ArduPilot as a
    float); returns the value the PARAM_VALUE echo carries, decoded."""
    name = SYSTEM_ID_PARAM[autopilot]
    wire = encode_bytewise(value, INT32) if autopilot == "px4" else float(value)
    kind = mavlink.MAV_PARAM_TYPE_INT32 if autopilot == "px4" else mavlink.MAV_PARAM_TYPE_INT16
    pilot.mav.param_set_send(pilot.vehicle.system_id, 1, name.encode(), wire, kind)
    echo = pilot.wait_message("PARAM_VALUE", 1.0, lambda m: m.param_id == name)
    return pilot.vehicle.params[name] if autopilot == "px4" else echo.param_value


@pytest.mark.parametrize("autopilot", ["px4", "ardupilot"])
def test_the_system_id_set_at_boot_is_the_one_the_vehicle_speaks_and_answers_as(autopilot):
    pilot = booted(autopilot, **{SYSTEM_ID_PARAM[autopilot]: 3})
    pilot.wait_for(lambda: heartbeat_sources(pilot, 0), 2.0, "a heartbeat")
    assert heartbeat_sources(pilot, 0) == {3} and pilot.vehicle.system_id == 3
    assert command_to(pilot, 1, mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HOME_POSITION) is None
    assert command_to(pilot, 3, mavlink.MAV_CMD_REQUEST_MESSAGE,
                      mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION) == mavlink.MAV_RESULT_ACCEPTED


@pytest.mark.parametrize("autopilot", ["px4", "ardupilot"])
def test_a_new_system_id_takes_effect_after_a_reboot(autopilot):
    pilot = booted(autopilot)
    assert set_system_id(pilot, autopilot, 2) == 2.0
    before = len(pilot.received)
    pilot.vehicle.run(2.0)
    pilot.step()
    assert heartbeat_sources(pilot, before) == {1}  # stored, not yet in use
    assert command_to(pilot, 1, REBOOT, 1) == mavlink.MAV_RESULT_ACCEPTED
    pilot.wait_for(lambda: pilot.vehicle.reboots == 1, 1.0, "the reboot")
    after = len(pilot.received)
    pilot.wait_for(lambda: heartbeat_sources(pilot, after), 10.0, "a heartbeat after the reboot")
    assert heartbeat_sources(pilot, after) == {2} and pilot.vehicle.system_id == 2


@pytest.mark.parametrize("autopilot, refusal", [("px4", mavlink.MAV_RESULT_DENIED),
                                                ("ardupilot", mavlink.MAV_RESULT_FAILED)])
def test_a_reboot_is_refused_while_armed(autopilot, refusal):
    pilot = booted(autopilot)
    pilot.set_mode(CopterMode.GUIDED if autopilot == "ardupilot" else FlightMode.HOLD)
    assert pilot.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_ACCEPTED
    assert pilot.command(REBOOT, 1) == refusal
    pilot.vehicle.run(1.0)
    assert pilot.vehicle.reboots == 0 and pilot.vehicle.autopilot.armed


def test_px4_does_nothing_for_0_and_ardupilot_knows_only_reboot_and_bootloader():
    px4 = booted("px4")
    assert px4.command(REBOOT, 0) == mavlink.MAV_RESULT_ACCEPTED
    assert px4.command(REBOOT, 2) == mavlink.MAV_RESULT_DENIED
    px4.vehicle.run(1.0)
    assert px4.vehicle.reboots == 0
    ardupilot = booted("ardupilot")
    assert ardupilot.command(REBOOT, 0) == mavlink.MAV_RESULT_UNSUPPORTED
    assert ardupilot.command(REBOOT, 2) == mavlink.MAV_RESULT_UNSUPPORTED
