"""Every command's ACK, offboard rules, setpoint frames and masks, parameters: over the in-memory link.

The client is pymavlink (MAVLink 2 bytes through :class:`MemoryMavConnection`), the vehicle runs in lockstep.
"""
from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.px4_modes import FlightMode
from sitl_bridge.scripted_flight import LockstepPilot
from sitl_bridge.vehicle import VehicleConfig

ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
TEMPORARILY_REJECTED = mavlink.MAV_RESULT_TEMPORARILY_REJECTED
DENIED = mavlink.MAV_RESULT_DENIED
UNSUPPORTED = mavlink.MAV_RESULT_UNSUPPORTED
ARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM


@pytest.fixture
def pilot() -> LockstepPilot:
    p = LockstepPilot.create(VehicleConfig(seed=1))
    p.wait_for(lambda: p.vehicle.autopilot.gps_ok, 2.0, "GPS")
    return p


def airborne(pilot: LockstepPilot, alt_m: float = 10.0) -> LockstepPilot:
    pilot.set_param("MIS_TAKEOFF_ALT", alt_m)
    assert pilot.command(ARM, 1) == ACCEPTED
    assert pilot.command(mavlink.MAV_CMD_NAV_TAKEOFF, *[math.nan] * 7) == ACCEPTED
    pilot.wait_for(lambda: pilot.vehicle.autopilot.mode is FlightMode.HOLD and not pilot.vehicle.state.on_ground,
                   30.0, "takeoff")
    return pilot


def test_arm_disarm_results_and_idempotence(pilot):
    assert pilot.command(ARM, 1) == ACCEPTED
    assert pilot.command(ARM, 1) == ACCEPTED  # a retransmission: same answer, still armed
    assert pilot.vehicle.autopilot.armed
    assert pilot.command(ARM, 0) == ACCEPTED
    assert pilot.command(ARM, 0) == ACCEPTED
    assert not pilot.vehicle.autopilot.armed
    assert pilot.command(ARM, 7) == DENIED  # neither arm nor disarm


def test_ack_is_addressed_to_the_sender(pilot):
    pilot.command(ARM, 1)
    ack = next(m for m in pilot.received if m.get_type() == "COMMAND_ACK")
    assert (ack.target_system, ack.target_component) == (255, 190)
    assert (ack.get_srcSystem(), ack.get_srcComponent()) == (1, 1)


def test_arming_refused_without_gps_unless_forced(pilot):
    autopilot, state = pilot.vehicle.autopilot, pilot.vehicle.state
    autopilot.gps_ok = False  # as before the first GPS fix
    assert autopilot.handle_command(ARM, (1, 0, 0, 0, 0, 0, 0), 0.0, state) == TEMPORARILY_REJECTED
    assert not autopilot.armed
    assert autopilot.handle_command(ARM, (1, 21196, 0, 0, 0, 0, 0), 0.0, state) == ACCEPTED  # forced
    assert autopilot.armed


def test_disarm_in_air_needs_force(pilot):
    airborne(pilot)
    assert pilot.command(ARM, 0) == TEMPORARILY_REJECTED
    assert pilot.vehicle.autopilot.armed
    assert pilot.command(ARM, 0, 21196) == ACCEPTED
    assert not pilot.vehicle.autopilot.armed


def test_takeoff_results(pilot):
    assert pilot.command(mavlink.MAV_CMD_NAV_TAKEOFF, *[math.nan] * 7) == TEMPORARILY_REJECTED  # disarmed
    assert pilot.command(ARM, 1) == ACCEPTED
    home_alt = pilot.vehicle.config.home.alt_m
    # param7 is AMSL: 10 (meant as "10 m up") is below home, so PX4's minimum, MIS_TAKEOFF_ALT, is used
    assert pilot.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, 10.0) == ACCEPTED
    assert pilot.vehicle.autopilot.takeoff_alt_m == pilot.vehicle.params["MIS_TAKEOFF_ALT"]
    assert any("minimum takeoff altitude" in m.text for m in pilot.received if m.get_type() == "STATUSTEXT")
    assert pilot.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, home_alt + 6) == ACCEPTED
    assert pilot.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, home_alt + 6) == ACCEPTED
    assert pilot.vehicle.autopilot.mode is FlightMode.TAKEOFF
    pilot.wait_for(lambda: pilot.vehicle.autopilot.mode is FlightMode.HOLD, 20.0, "takeoff")
    pilot.vehicle.run(3.0)
    assert -pilot.vehicle.state.down_m == pytest.approx(6.0, abs=0.3)


def test_takeoff_uses_mis_takeoff_alt_when_param7_is_nan(pilot):
    assert pilot.set_param("MIS_TAKEOFF_ALT", 4.0) == pytest.approx(4.0)
    airborne(pilot, 4.0)
    pilot.vehicle.run(3.0)
    assert -pilot.vehicle.state.down_m == pytest.approx(4.0, abs=0.3)


def test_land_rtl_and_set_mode(pilot):
    airborne(pilot)
    pilot.stream = (2.0, 0.0, 0.0, mavlink.MAV_FRAME_LOCAL_NED)
    pilot.wait_for(lambda: not pilot.vehicle.autopilot.offboard_signal_lost(pilot.vehicle.time_s), 3.0, "stream")
    assert pilot.set_mode(FlightMode.OFFBOARD) == ACCEPTED
    pilot.wait_for(lambda: pilot.vehicle.state.north_m > 10.0, 20.0, "fly out")
    pilot.stream = None
    assert pilot.command(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH) == ACCEPTED
    assert pilot.command(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH) == ACCEPTED
    assert pilot.heartbeat_mode() is FlightMode.RTL
    # RTL climbs to RTL_RETURN_ALT before it turns home
    pilot.wait_for(lambda: -pilot.vehicle.state.down_m > 29.0, 20.0, "RTL climb")
    assert pilot.vehicle.state.north_m > 10.0
    assert pilot.set_mode(FlightMode.HOLD) == ACCEPTED
    assert pilot.command(mavlink.MAV_CMD_NAV_LAND) == ACCEPTED
    assert pilot.heartbeat_mode() is FlightMode.LAND
    landed_at = pilot.wait_for(lambda: pilot.vehicle.state.on_ground, 60.0, "landing")
    assert landed_at > 20.0  # PX4 speeds: 1.5 m/s high up, 0.7 m/s near the ground
    pilot.wait_for(lambda: not pilot.vehicle.autopilot.armed, 3.0, "auto-disarm")
    assert pilot.vehicle.state.north_m > 10.0  # landed where LAND was requested, not at home


def test_do_set_mode_encodings(pilot):
    assert pilot.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 3, 0) == ACCEPTED  # POSCTL
    assert pilot.heartbeat_mode() is FlightMode.POSCTL
    assert pilot.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 4, 3) == ACCEPTED  # AUTO.LOITER
    assert pilot.heartbeat_mode() is FlightMode.HOLD
    assert pilot.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 1, 0) == DENIED  # MANUAL is not emulated
    assert pilot.command(mavlink.MAV_CMD_DO_SET_MODE, 0, 4, 3) == DENIED  # no CUSTOM_MODE_ENABLED flag


def test_mode_change_is_announced_by_an_immediate_heartbeat(pilot):
    pilot.vehicle.run(1.5)  # past a scheduled heartbeat
    pilot.mav.command_long_send(1, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, 1, 3, 0, 0, 0, 0, 0)
    sent_at = pilot.vehicle.time_s
    beat = pilot.wait_message("HEARTBEAT", 0.2, lambda m: FlightMode.from_custom_mode(m.custom_mode) is FlightMode.POSCTL)
    assert beat is not None and pilot.vehicle.time_s - sent_at <= 0.02


def test_message_interval_request_message_and_capabilities(pilot):
    gpi = mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT
    assert pilot.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, gpi, 20_000) == ACCEPTED  # 50 Hz
    start = len(pilot.received)
    t0 = pilot.vehicle.time_s
    pilot.wait_for(lambda: pilot.vehicle.time_s - t0 >= 2.0, 3.0, "2 s")
    count = sum(1 for m in pilot.received[start:] if m.get_type() == "GLOBAL_POSITION_INT")
    assert 95 <= count <= 105
    assert pilot.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, gpi, -1) == ACCEPTED  # off
    start = len(pilot.received)
    t0 = pilot.vehicle.time_s
    pilot.wait_for(lambda: pilot.vehicle.time_s - t0 >= 1.0, 2.0, "1 s")
    assert not any(m.get_type() == "GLOBAL_POSITION_INT" for m in pilot.received[start:])
    assert pilot.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 99999, 100_000) == DENIED  # unknown message id
    before = len(pilot.received)
    assert pilot.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HOME_POSITION) == ACCEPTED
    home = next(m for m in pilot.received[before:] if m.get_type() == "HOME_POSITION")
    assert home.latitude == round(pilot.vehicle.config.home.lat_deg * 1e7)
    before = len(pilot.received)
    assert pilot.command(mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1) == ACCEPTED
    assert any(m.get_type() == "AUTOPILOT_VERSION" for m in pilot.received[before:])


def test_camera_zoom_and_unsupported_commands(pilot):
    assert pilot.command(mavlink.MAV_CMD_SET_CAMERA_ZOOM, mavlink.ZOOM_TYPE_RANGE, 40) == ACCEPTED
    assert pilot.vehicle.autopilot.zoom_percent == 40
    assert pilot.command(mavlink.MAV_CMD_SET_CAMERA_ZOOM, mavlink.ZOOM_TYPE_RANGE, 140) == DENIED
    assert pilot.command(mavlink.MAV_CMD_DO_SET_SERVO, 1, 1500) == UNSUPPORTED
    assert pilot.command(mavlink.MAV_CMD_NAV_WAYPOINT) == UNSUPPORTED


def test_command_int_is_handled_like_command_long(pilot):
    pilot.mav.command_int_send(1, 1, mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0,
                               0, 0, 0, 0, 0, 0, 0)
    ack = pilot.wait_message("COMMAND_ACK", 0.5)
    assert (ack.command, ack.result) == (mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, ACCEPTED)


def test_commands_for_other_systems_are_not_answered(pilot):
    pilot.mav.command_long_send(42, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0)
    pilot.vehicle.run(0.5)
    for _ in range(3):
        pilot.step()
    assert not any(m.get_type() == "COMMAND_ACK" for m in pilot.received)
    assert not pilot.vehicle.autopilot.armed


def test_flight_status_is_the_neutral_view_of_px4_modes(pilot):
    autopilot = pilot.vehicle.autopilot
    assert (autopilot.status.phase, autopilot.status.mode_name) == ("on_ground", "HOLD")
    pilot.set_param("MIS_TAKEOFF_ALT", 6.0)
    pilot.command(ARM, 1)
    pilot.command(mavlink.MAV_CMD_NAV_TAKEOFF, *[math.nan] * 7)
    pilot.vehicle.run(1.0)
    assert autopilot.status.phase == "taking_off"
    pilot.wait_for(lambda: autopilot.mode is FlightMode.HOLD, 20.0, "takeoff")
    assert autopilot.status.phase == "holding"
    pilot.send_velocity(1.0, 0.0, 0.0)
    assert pilot.set_mode(FlightMode.OFFBOARD) == ACCEPTED
    status = autopilot.status
    assert (status.phase, status.mode_name, status.setpoint_timeout_s) == ("guided", "OFFBOARD", 1.0)
    assert status.companion_in_control and status.last_setpoint_s == autopilot.setpoint.time_s
    assert pilot.command(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH) == ACCEPTED
    assert autopilot.status.phase == "returning"
    assert pilot.command(mavlink.MAV_CMD_NAV_LAND) == ACCEPTED
    assert autopilot.status.phase == "landing"
