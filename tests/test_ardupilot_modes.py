"""The ArduPilot Copter personality's modes, flown by pymavlink over the in-memory link in lockstep.

Each test states what ArduCopter does (its source is cited in docs/sitl.md) and checks the simulated vehicle does the
same: heartbeat fields, mode numbers, arming and its texts, takeoff, the neutral flight status, and STABILIZE in the air
without a pilot.
"""
from __future__ import annotations

import pytest
from ardupilot_helpers import ACCEPTED, ARM, DENIED, FAILED, TAKEOFF, airborne, copter, fly, last, texts
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.ardupilot.modes import CopterMode


# ---------------------------------------------------------------- HEARTBEAT and modes
def test_heartbeat_is_arducopter_in_stabilize_on_the_ground():
    beat = last(copter(), "HEARTBEAT")
    assert (beat.autopilot, beat.type, beat.custom_mode) == (mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                                             mavlink.MAV_TYPE_QUADROTOR, 0)
    assert beat.base_mode == (mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
                              | mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED)
    assert beat.system_status == mavlink.MAV_STATE_STANDBY
    assert mavutil.mode_string_v10(beat) == "STABILIZE"


def test_heartbeat_in_guided_flight_and_landed_but_armed():
    pilot = copter()
    pilot.set_mode(CopterMode.GUIDED)
    pilot.command(ARM, 1)
    armed_on_ground = last(pilot, "HEARTBEAT")
    assert armed_on_ground.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    assert armed_on_ground.system_status == mavlink.MAV_STATE_STANDBY  # ArduPilot: landed is STANDBY, armed or not
    assert not armed_on_ground.base_mode & mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
    pilot.command(TAKEOFF, 0, 0, 0, 0, 0, 0, 5.0)
    fly(pilot, 3.0)
    flying = last(pilot, "HEARTBEAT")
    assert flying.system_status == mavlink.MAV_STATE_ACTIVE
    assert flying.base_mode & mavlink.MAV_MODE_FLAG_GUIDED_ENABLED and mavutil.mode_string_v10(flying) == "GUIDED"


@pytest.mark.parametrize("mode", list(CopterMode))
def test_every_emulated_mode_number_is_accepted_and_decodes_like_pymavlink(mode):
    pilot = copter()
    assert pilot.set_mode(mode) == ACCEPTED  # disarmed: any mode may be entered
    beat = pilot.wait_message("HEARTBEAT", 1.5)
    assert beat.custom_mode == int(mode) and mavutil.mode_mapping_acm[beat.custom_mode] == mode.name


def test_set_mode_message_is_acked_as_command_11_and_bad_modes_fail():
    pilot = copter()
    pilot.mav.set_mode_send(1, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, int(CopterMode.LOITER))
    ack = pilot.wait_message("COMMAND_ACK", 0.5, lambda m: m.command == mavlink.MAVLINK_MSG_ID_SET_MODE)
    assert ack.result == ACCEPTED and pilot.vehicle.autopilot.mode is CopterMode.LOITER
    seen = len(pilot.received)
    assert pilot.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 99) == FAILED
    assert "No such mode 99" in texts(pilot, seen)
    assert pilot.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 2) == FAILED  # ALT_HOLD exists but is not emulated
    assert pilot.command(mavlink.MAV_CMD_DO_SET_MODE, 0, 4) == DENIED  # only custom modes
    assert pilot.vehicle.autopilot.mode is CopterMode.LOITER


def test_armed_mode_change_needs_a_position():
    pilot = copter()
    assert pilot.command(ARM, 1) == ACCEPTED  # STABILIZE: no GPS needed
    pilot.vehicle.autopilot.gps_ok = False
    seen = len(pilot.received)
    assert pilot.vehicle.autopilot.set_mode(int(CopterMode.GUIDED), pilot.vehicle.time_s, pilot.vehicle.state,
                                            "test") is False
    pilot.step()
    assert "Mode change to GUIDED failed: requires position" in texts(pilot, seen)


# ---------------------------------------------------------------- arming
@pytest.mark.parametrize("mode", [CopterMode.RTL, CopterMode.LAND, CopterMode.BRAKE])
def test_arming_refused_in_modes_that_do_not_allow_it(mode):
    pilot = copter()
    pilot.set_mode(mode)
    seen = len(pilot.received)
    assert pilot.command(ARM, 1) == FAILED
    assert "Arm: Mode not armable" in texts(pilot, seen) and not pilot.vehicle.autopilot.armed
    assert pilot.command(ARM, 1, 2989) == ACCEPTED  # ArduPilot's force-arm value (21196 is for disarming)


def test_prearm_failure_text_and_force_values():
    pilot = copter()
    pilot.set_mode(CopterMode.GUIDED)
    pilot.vehicle.autopilot.gps_ok = False
    ap, state = pilot.vehicle.autopilot, pilot.vehicle.state
    assert ap.handle_command(ARM, (1, 21196, 0, 0, 0, 0, 0), 0.0, state) == FAILED  # 21196 does not force an arm
    assert [e.text for e in ap.events][-1] == "PreArm: Need Position Estimate"
    assert ap.handle_command(ARM, (1, 2989, 0, 0, 0, 0, 0), 0.0, state) == ACCEPTED
    assert [e.text for e in ap.events][-1] == "Arming motors"


def test_disarm_in_the_air_fails_unless_forced():
    pilot = airborne()
    assert pilot.command(ARM, 0) == FAILED and pilot.vehicle.autopilot.armed
    assert pilot.command(ARM, 0, 21196) == ACCEPTED and not pilot.vehicle.autopilot.armed
    assert "Disarming motors" in texts(pilot)


# ---------------------------------------------------------------- takeoff
def test_takeoff_is_relative_to_home_and_stays_in_guided():
    pilot = copter()
    pilot.set_mode(CopterMode.GUIDED)
    assert pilot.command(TAKEOFF, 0, 0, 0, 0, 0, 0, 10.0) == FAILED  # disarmed
    pilot.command(ARM, 1)
    assert pilot.command(TAKEOFF, 0, 0, 0, 0, 0, 0, 10.0) == ACCEPTED  # 10 m above home, not 10 m AMSL
    fly(pilot, 12.0)
    assert -pilot.vehicle.state.down_m == pytest.approx(10.0, abs=0.4)
    assert pilot.vehicle.autopilot.mode is CopterMode.GUIDED and pilot.heartbeat_mode() is CopterMode.GUIDED
    assert pilot.command(TAKEOFF, 0, 0, 0, 0, 0, 0, 20.0) == FAILED  # already flying
    fly(pilot, 5.0)
    assert -pilot.vehicle.state.down_m == pytest.approx(10.0, abs=0.4)  # holds the takeoff altitude


def test_takeoff_rules_frame_mode_and_loiter():
    pilot = copter()
    pilot.command(ARM, 1)
    assert pilot.command(TAKEOFF, 0, 0, 0, 0, 0, 0, 10.0) == FAILED  # STABILIZE has no user takeoff
    pilot.set_mode(CopterMode.LOITER)
    pilot.mav.command_int_send(1, 1, mavlink.MAV_FRAME_GLOBAL, TAKEOFF, 0, 0, 0, 0, 0, 0, 0, 0, 8.0)
    assert pilot.wait_message("COMMAND_ACK", 0.5).result == DENIED  # COMMAND_INT must be GLOBAL_RELATIVE_ALT
    assert pilot.command(TAKEOFF, 0, 0, 0, 0, 0, 0, 8.0) == ACCEPTED  # LOITER has a user takeoff
    fly(pilot, 8.0)
    assert -pilot.vehicle.state.down_m == pytest.approx(8.0, abs=0.4)
    assert pilot.vehicle.autopilot.mode is CopterMode.LOITER


def test_landed_state_goes_takeoff_in_air():
    pilot = copter(telemetry_rates_hz={mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 5.0})
    pilot.set_mode(CopterMode.GUIDED)
    pilot.command(ARM, 1)
    pilot.command(TAKEOFF, 0, 0, 0, 0, 0, 0, 6.0)
    fly(pilot, 8.0)
    states = [m.landed_state for m in pilot.received if m.get_type() == "EXTENDED_SYS_STATE"]
    collapsed = [s for i, s in enumerate(states) if i == 0 or s != states[i - 1]]
    assert collapsed == [mavlink.MAV_LANDED_STATE_ON_GROUND, mavlink.MAV_LANDED_STATE_TAKEOFF,
                         mavlink.MAV_LANDED_STATE_IN_AIR]


# ---------------------------------------------------------------- flight status and STABILIZE
def test_flight_status_is_the_neutral_view():
    pilot = copter()
    assert pilot.vehicle.autopilot.status.phase == "on_ground"
    pilot.set_mode(CopterMode.GUIDED)
    pilot.command(ARM, 1)
    pilot.command(TAKEOFF, 0, 0, 0, 0, 0, 0, 6.0)
    fly(pilot, 1.0)
    assert pilot.vehicle.autopilot.status.phase == "taking_off"
    fly(pilot, 6.0)
    pilot.send_velocity(1.0, 0.0, 0.0)
    fly(pilot, 0.1)
    status = pilot.vehicle.autopilot.status
    assert (status.phase, status.mode_name, status.setpoint_timeout_s) == ("guided", "GUIDED", 3.0)
    assert status.companion_in_control and status.last_setpoint_s == pytest.approx(pilot.vehicle.time_s, abs=0.11)
    pilot.set_mode(CopterMode.BRAKE)
    assert pilot.vehicle.autopilot.status.phase == "holding"
    pilot.command(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    assert pilot.vehicle.autopilot.status.phase == "returning"


def test_stabilize_in_the_air_without_a_pilot_cuts_the_thrust():
    """No RC input means throttle low: switching a flying copter to STABILIZE drops it (what really happens)."""
    pilot = airborne(alt_m=12.0)
    assert pilot.set_mode(CopterMode.STABILIZE) == ACCEPTED
    assert pilot.vehicle.autopilot.status.phase == "manual" and not pilot.vehicle.autopilot.motors_running
    fly(pilot, 1.0)
    assert pilot.vehicle.state.vd_mps > 5.0  # falling
    pilot.wait_for(lambda: pilot.vehicle.state.on_ground, 5, "the ground")
