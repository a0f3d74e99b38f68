"""The ArduPilot Copter personality's way down and its failsafes, flown by pymavlink over the in-memory link in
lockstep.

Each test states what ArduCopter does (its source is cited in docs/sitl.md) and checks the simulated vehicle does the
same: RTL (RTL_ALT and the cone slope), LAND, auto-disarm, and the GCS and battery failsafes.
"""
from __future__ import annotations

import math

import pytest
from ardupilot_helpers import ACCEPTED, ARM, LOCAL_NED, airborne, copter, fly, last, texts
from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.ardupilot.modes import CopterMode
from sitl_bridge.scripted_flight import LockstepPilot


# ---------------------------------------------------------------- RTL, LAND and disarming
def test_rtl_climbs_to_rtl_alt_returns_hovers_lands_and_disarms():
    pilot = airborne()
    pilot.stream = (6.0, 0.0, 0.0, LOCAL_NED)
    pilot.wait_for(lambda: pilot.vehicle.state.north_m > 40.0, 30, "fly out")
    pilot.stream = None
    assert pilot.command(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH) == ACCEPTED
    pilot.wait_for(lambda: -pilot.vehicle.state.down_m > 14.6, 20, "climb to RTL_ALT (15 m)")
    assert pilot.vehicle.state.north_m > 38.0  # climbs before it turns home
    pilot.wait_for(lambda: math.hypot(pilot.vehicle.state.north_m, pilot.vehicle.state.east_m) < 1.0, 30, "home")
    arrived = pilot.vehicle.time_s
    pilot.wait_for(lambda: pilot.vehicle.autopilot.rtl_state == "land", 10, "descent starts")
    assert pilot.vehicle.time_s - arrived == pytest.approx(5.0, abs=0.1)  # RTL_LOIT_TIME 5000 ms
    assert -pilot.vehicle.state.down_m == pytest.approx(15.0, abs=0.3)  # hovered at the return altitude
    pilot.wait_for(lambda: not pilot.vehicle.autopilot.armed, 60, "landing and disarm")
    assert pilot.vehicle.state.on_ground and pilot.vehicle.autopilot.mode is CopterMode.RTL  # stays in RTL
    assert "Disarming motors" in texts(pilot)


def test_rtl_near_home_climbs_less_by_the_cone_slope():
    pilot = airborne(alt_m=5.0)
    pilot.stream = (2.0, 0.0, 0.0, LOCAL_NED)
    pilot.wait_for(lambda: pilot.vehicle.state.north_m > 3.0, 10, "3 m out")
    pilot.stream = None
    pilot.command(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    distance = pilot.vehicle.state.north_m
    expected = max(min(15.0, max(distance * 3.0, -pilot.vehicle.state.down_m)), 2.0)
    assert -pilot.vehicle.autopilot.rtl_return_down_m == pytest.approx(expected, abs=0.3)
    assert expected < 15.0


def test_land_speeds_and_disarm_on_touchdown():
    pilot = airborne(alt_m=20.0)
    assert pilot.command(mavlink.MAV_CMD_NAV_LAND) == ACCEPTED
    fly(pilot, 4.0)
    assert pilot.vehicle.state.vd_mps == pytest.approx(1.5, abs=0.1)  # WPNAV_SPEED_DN above LAND_ALT_LOW
    pilot.wait_for(lambda: -pilot.vehicle.state.down_m < 8.0, 20, "below 10 m")
    fly(pilot, 2.0)
    assert pilot.vehicle.state.vd_mps == pytest.approx(0.5, abs=0.05)  # LAND_SPEED
    pilot.wait_for(lambda: pilot.vehicle.state.on_ground, 30, "touchdown")
    down_at = pilot.vehicle.time_s
    pilot.wait_for(lambda: not pilot.vehicle.autopilot.armed, 3, "disarm")
    assert pilot.vehicle.time_s - down_at == pytest.approx(1.0, abs=0.05)  # the land detector's second
    assert pilot.vehicle.autopilot.mode is CopterMode.LAND


def test_armed_on_the_ground_disarms_after_disarm_delay():
    pilot = copter({"DISARM_DELAY": 4})
    pilot.set_mode(CopterMode.GUIDED)
    armed_at = pilot.vehicle.time_s
    pilot.command(ARM, 1)
    pilot.wait_for(lambda: not pilot.vehicle.autopilot.armed, 8, "auto-disarm")
    assert pilot.vehicle.time_s - armed_at == pytest.approx(4.0, abs=0.1)


# ---------------------------------------------------------------- failsafes
def heartbeats_from(pilot: LockstepPilot, system_id: int, seconds: float) -> None:
    for _ in range(int(seconds)):
        pilot.mav.srcSystem = system_id
        pilot.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        pilot.mav.srcSystem = 255
        fly(pilot, 1.0)


def test_gcs_failsafe_counts_only_sysid_mygcs_heartbeats_then_returns():
    pilot = airborne({"FS_GCS_ENABLE": 1})
    heartbeats_from(pilot, 255, 3)
    lost_from = pilot.vehicle.time_s - 1.0
    heartbeats_from(pilot, 42, 3)  # another system's heartbeats do not keep the failsafe off
    pilot.wait_for(lambda: pilot.vehicle.autopilot.mode is CopterMode.RTL, 5, "GCS failsafe")
    assert pilot.vehicle.time_s - lost_from == pytest.approx(5.0, abs=0.1)  # FS_GCS_TIMEOUT
    assert "GCS Failsafe" in texts(pilot) and last(pilot, "HEARTBEAT").system_status == mavlink.MAV_STATE_CRITICAL
    heartbeats_from(pilot, 255, 2)
    assert "GCS Failsafe Cleared" in texts(pilot)


def test_gcs_failsafe_lets_pilot_controlled_modes_continue_by_default():
    pilot = airborne({"FS_GCS_ENABLE": 1})
    pilot.set_mode(CopterMode.LOITER)
    heartbeats_from(pilot, 255, 1)
    fly(pilot, 7.0)
    assert "GCS Failsafe - Continuing Pilot Control" in texts(pilot)  # FS_OPTIONS 16
    assert pilot.vehicle.autopilot.mode is CopterMode.LOITER


def test_no_gcs_failsafe_by_default():
    pilot = airborne()
    heartbeats_from(pilot, 255, 1)
    fly(pilot, 8.0)
    assert pilot.vehicle.autopilot.mode is CopterMode.GUIDED and not pilot.vehicle.autopilot.gcs_failsafe


def test_battery_failsafe_low_voltage_for_batt_low_timer_returns():
    pilot = airborne({"BATT_LOW_VOLT": 16.75, "BATT_FS_LOW_ACT": 2})
    battery = mavlink.MAV_SYS_STATUS_SENSOR_BATTERY
    assert pilot.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_SYS_STATUS) == ACCEPTED
    assert last(pilot, "SYS_STATUS").onboard_control_sensors_health & battery
    pilot.wait_for(lambda: pilot.vehicle.autopilot.battery_failsafe == 1, 60, "battery failsafe")
    low = next(t for t in texts(pilot) if t.startswith("Battery 1 is low"))
    assert low.endswith("mAh") and "V used" in low and "Battery Failsafe" in texts(pilot)
    assert pilot.vehicle.autopilot.mode is CopterMode.RTL
    assert last(pilot, "HEARTBEAT").system_status == mavlink.MAV_STATE_CRITICAL
    # GCS_Common.cpp update_sensor_status_flags: the battery is healthy only while it has not failed safe
    assert pilot.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_SYS_STATUS) == ACCEPTED
    status = last(pilot, "SYS_STATUS")
    assert status.onboard_control_sensors_enabled & battery and not status.onboard_control_sensors_health & battery


def test_batt_monitor_0_hides_the_battery_parameters_and_turns_the_battery_failsafe_off():
    """AP_BattMonitor_Params.cpp: BATT_MONITOR carries AP_PARAM_FLAG_ENABLE, so at 0 the other BATT_* are not listed,
    not answered and not settable, SYS_STATUS reports no battery (0 V, -1 A, -1 %, not enabled) and nothing fails safe
    on it."""
    pilot = airborne({"BATT_MONITOR": 0, "BATT_LOW_VOLT": 16.75, "BATT_FS_LOW_ACT": 2})  # monitored: RTL within 60 s
    before = len(pilot.received)
    pilot.mav.param_request_list_send(1, 1)
    fly(pilot, 1.0)
    listed = [m for m in pilot.received[before:] if m.get_type() == "PARAM_VALUE"]
    names = [m.param_id for m in listed]
    assert "BATT_MONITOR" in names and [n for n in names if n.startswith("BATT_")] == ["BATT_MONITOR"]
    assert {m.param_count for m in listed} == {len(names)} and sorted(m.param_index for m in listed) == \
        list(range(len(names)))
    before = len(pilot.received)
    pilot.mav.param_request_read_send(1, 1, b"BATT_FS_LOW_ACT", -1)
    pilot.mav.param_set_send(1, 1, b"BATT_FS_LOW_ACT", 1.0, mavlink.MAV_PARAM_TYPE_INT8)
    fly(pilot, 1.0)
    assert not [m for m in pilot.received[before:] if m.get_type() == "PARAM_VALUE"]
    assert pilot.vehicle.params["BATT_FS_LOW_ACT"] == 2  # the hidden value is kept for when the monitor returns
    fly(pilot, 60.0)
    assert pilot.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_SYS_STATUS) == ACCEPTED
    before = len(pilot.received)  # GCS_Common.cpp handle_command_request_message: ACCEPTED, then nothing to send
    assert pilot.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_BATTERY_STATUS) == ACCEPTED
    fly(pilot, 0.5)
    assert not [m for m in pilot.received[before:] if m.get_type() == "BATTERY_STATUS"]
    status = last(pilot, "SYS_STATUS")
    assert (status.voltage_battery, status.current_battery, status.battery_remaining) == (0, -1, -1)
    battery = mavlink.MAV_SYS_STATUS_SENSOR_BATTERY  # present, but neither enabled nor healthy (GCS_Common.cpp)
    assert status.onboard_control_sensors_present & battery
    assert not status.onboard_control_sensors_enabled & battery and not status.onboard_control_sensors_health & battery
    assert pilot.vehicle.autopilot.battery_failsafe == 0 and pilot.vehicle.autopilot.mode is CopterMode.GUIDED
    assert pilot.set_param("BATT_MONITOR", 4) == 4  # visible again, with the kept value
    pilot.mav.param_request_read_send(1, 1, b"BATT_FS_LOW_ACT", -1)
    assert pilot.wait_message("PARAM_VALUE", 0.5, lambda m: m.param_id == "BATT_FS_LOW_ACT").param_value == 2.0
