"""The ArduPilot Copter personality's parameters and streams, flown by pymavlink over the in-memory link in lockstep.

Each test states what ArduCopter does (its source is cited in docs/sitl.md) and checks the simulated vehicle does the
same: float parameters and capabilities, stream requests and SRx_ rates, and HOME_POSITION.
"""
from __future__ import annotations

import pytest
from ardupilot_helpers import ACCEPTED, ARM, FAILED, copter, fly
from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.ardupilot.modes import CopterMode
from sitl_bridge.scripted_flight import LockstepPilot


# ---------------------------------------------------------------- parameters, capabilities, streams, home
def test_parameters_are_floats_with_ardupilot_types():
    pilot = copter()
    pilot.mav.param_request_read_send(1, 1, b"FS_GCS_ENABLE", -1)
    fs = pilot.wait_message("PARAM_VALUE", 0.5)
    assert (fs.param_type, fs.param_value) == (mavlink.MAV_PARAM_TYPE_INT8, 0.0)  # a float, not bytewise
    pilot.mav.param_set_send(1, 1, b"RTL_ALT", 2499.995, mavlink.MAV_PARAM_TYPE_INT32)
    echo = pilot.wait_message("PARAM_VALUE", 0.5)
    assert (echo.param_id, echo.param_value) == ("RTL_ALT", 2500.0)  # AP_Param::set_float: +0.01, truncated
    assert pilot.set_param("GUID_TIMEOUT", 1.5) == pytest.approx(1.5)
    before = len(pilot.received)
    assert pilot.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION) == ACCEPTED
    version = next(m for m in pilot.received[before:] if m.get_type() == "AUTOPILOT_VERSION")
    assert version.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    assert version.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
    assert not version.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
    assert version.flight_sw_version >> 24 == 4
    # GCS_Common.cpp handle_command_request_message: an id with no ap_message is FAILED (PX4 says DENIED)
    assert pilot.command(mavlink.MAV_CMD_REQUEST_MESSAGE, 65000) == mavlink.MAV_RESULT_FAILED


def rate(pilot: LockstepPilot, msg_type: str, seconds: float) -> float:
    seen = len(pilot.received)
    fly(pilot, seconds)
    return sum(1 for m in pilot.received[seen:] if m.get_type() == msg_type) / seconds


def test_nothing_streams_until_requested_then_data_streams_and_intervals():
    pilot = copter()
    assert rate(pilot, "GLOBAL_POSITION_INT", 3.0) == 0.0 and rate(pilot, "HEARTBEAT", 4.0) == pytest.approx(1.0)
    pilot.mav.request_data_stream_send(1, 1, mavlink.MAV_DATA_STREAM_POSITION, 5, 1)
    assert rate(pilot, "GLOBAL_POSITION_INT", 4.0) == pytest.approx(5.0, abs=0.3)
    assert rate(pilot, "ATTITUDE", 2.0) == 0.0  # another group
    assert pilot.vehicle.params["SR0_POSITION"] == 5
    pilot.mav.request_data_stream_send(1, 1, mavlink.MAV_DATA_STREAM_ALL, 2, 1)
    assert rate(pilot, "ATTITUDE", 4.0) == pytest.approx(2.0, abs=0.3)
    pilot.mav.request_data_stream_send(1, 1, mavlink.MAV_DATA_STREAM_ALL, 0, 0)
    assert rate(pilot, "LOCAL_POSITION_NED", 2.0) == 0.0
    assert pilot.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
                         500_000) == ACCEPTED
    assert rate(pilot, "EXTENDED_SYS_STATE", 4.0) == pytest.approx(2.0, abs=0.3)


def test_sr_parameters_at_boot_set_the_link_rates():
    pilot = copter({"SR0_POSITION": 4, "SR0_EXTRA1": 10})
    assert rate(pilot, "LOCAL_POSITION_NED", 3.0) == pytest.approx(4.0, abs=0.4)
    assert rate(pilot, "ATTITUDE", 2.0) == pytest.approx(10.0, abs=0.6)


def test_home_position_when_set_at_arming_and_on_request_never_streamed():
    pilot = copter()
    assert sum(m.get_type() == "HOME_POSITION" for m in pilot.received) == 1  # sent when home is first set
    fly(pilot, 5.0)
    assert sum(m.get_type() == "HOME_POSITION" for m in pilot.received) == 1
    seen = len(pilot.received)
    assert pilot.command(mavlink.MAV_CMD_GET_HOME_POSITION) == ACCEPTED
    home = next(m for m in pilot.received[seen:] if m.get_type() == "HOME_POSITION")
    assert (home.latitude, home.altitude) == (round(pilot.vehicle.config.home.lat_deg * 1e7), 488_000)
    seen = len(pilot.received)
    pilot.set_mode(CopterMode.GUIDED)
    pilot.command(ARM, 1)
    assert any(m.get_type() == "HOME_POSITION" for m in pilot.received[seen:])  # re-set where it arms


def test_no_home_yet_means_an_accepted_request_and_nothing_sent(monkeypatch):
    """GCS_Common.cpp: REQUEST_MESSAGE HOME_POSITION is ACCEPTED and send_home_position() returns before home is set
    (GET_HOME_POSITION says FAILED then)."""
    pilot = copter()
    suite = type(pilot.vehicle.sensors)
    update = suite.update
    monkeypatch.setattr(suite, "update", lambda self, *args: (update(self, *args), setattr(self, "gps", None)))
    fly(pilot, 0.1)  # a receiver without a fix
    seen = len(pilot.received)
    assert pilot.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HOME_POSITION) == ACCEPTED
    assert pilot.command(mavlink.MAV_CMD_GET_HOME_POSITION) == FAILED
    assert not [m for m in pilot.received[seen:] if m.get_type() == "HOME_POSITION"]
