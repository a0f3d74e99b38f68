"""The simulated PX4's failsafe reaction (sitl_bridge/px4/failsafes.py), flown in lockstep with pymavlink:
COM_FAIL_ACT_T's Hold before a geofence or battery Return / Land, a mode switch during it as a user takeover, and the
battery failsafe with COM_LOW_BAT_ACT (PX4's default only warns), each with the STATUSTEXTs PX4 sends."""
from __future__ import annotations

import dataclasses

import pytest
from pymavlink.dialects.v20 import common as mavlink
from test_autopilot_fences import LOCAL_NED, PX4_DISTANCE_TEXT, fly, px4_in_offboard, texts

from sitl_bridge.px4.modes import FlightMode
from sitl_bridge.scripted_flight import LockstepPilot

HOLD_TEXT = "Failsafe activated, entering Hold for 5 seconds\t"
ACTIVATED = "Failsafe activated\t"
ACCEPTED = mavlink.MAV_RESULT_ACCEPTED


def mode_changes(pilot: LockstepPilot, since: int = 0) -> list[tuple[float, str]]:
    """(vehicle time, mode) at each change of the vehicle's mode as seen in its HEARTBEATs."""
    changes: list[tuple[float, str]] = []
    for m in pilot.received[since:]:
        if m.get_type() == "HEARTBEAT":
            mode = FlightMode.from_custom_mode(m.custom_mode).name
            if not changes or changes[-1][1] != mode:
                changes.append((m._vehicle_time, mode))
    return changes


@pytest.fixture(autouse=True)
def stamp_heartbeats(monkeypatch):
    """Stamp each received message with the vehicle's clock, to time the Hold in simulated seconds."""
    original = LockstepPilot.step

    def step(self):
        before = len(self.received)
        original(self)
        for m in self.received[before:]:
            m._vehicle_time = self.vehicle.time_s
    monkeypatch.setattr(LockstepPilot, "step", step)


def set_battery(pilot: LockstepPilot, fraction: float) -> None:
    vehicle = pilot.vehicle
    capacity_wh = vehicle.config.airframe.battery_capacity_wh
    vehicle.state = dataclasses.replace(vehicle.state, battery_wh=fraction * capacity_wh)


def test_a_geofence_return_holds_com_fail_act_t_first_then_returns():
    pilot = px4_in_offboard({"GF_MAX_HOR_DIST": 60.0, "GF_ACTION": 3})
    start = len(pilot.received)
    pilot.wait_for(lambda: pilot.vehicle.autopilot.mode is FlightMode.RTL, 40.0, "geofence return")
    fly(pilot, 0.5)
    changes = mode_changes(pilot, start)
    assert [mode for _, mode in changes] == ["OFFBOARD", "HOLD", "RTL"]
    assert changes[2][0] - changes[1][0] == pytest.approx(5.0, abs=0.3)
    said = texts(pilot, start)
    assert said[:3] == [PX4_DISTANCE_TEXT, HOLD_TEXT, ACTIVATED]


def test_a_mode_switch_during_the_hold_is_a_takeover_and_the_return_never_comes():
    pilot = px4_in_offboard({"GF_MAX_HOR_DIST": 60.0, "GF_ACTION": 3})
    pilot.wait_for(lambda: pilot.vehicle.autopilot.mode is FlightMode.HOLD, 40.0, "the failsafe's hold")
    pilot.stream = (-5.0, 0.0, 0.0, LOCAL_NED)  # back towards home
    fly(pilot, 1.0)
    assert pilot.set_mode(FlightMode.OFFBOARD) == ACCEPTED
    fly(pilot, 8.0)
    assert pilot.vehicle.autopilot.mode is FlightMode.OFFBOARD and ACTIVATED not in texts(pilot)


def test_without_the_delay_the_return_is_immediate():
    pilot = px4_in_offboard({"GF_MAX_HOR_DIST": 60.0, "GF_ACTION": 3, "COM_FAIL_ACT_T": 0.0})
    start = len(pilot.received)
    pilot.wait_for(lambda: pilot.vehicle.autopilot.mode is not FlightMode.OFFBOARD, 40.0, "geofence return")
    assert pilot.vehicle.autopilot.mode is FlightMode.RTL and HOLD_TEXT not in texts(pilot, start)


def test_a_geofence_hold_is_never_delayed():
    pilot = px4_in_offboard({"GF_MAX_HOR_DIST": 60.0, "GF_ACTION": 2})
    start = len(pilot.received)
    pilot.wait_for(lambda: pilot.vehicle.autopilot.mode is FlightMode.HOLD, 40.0, "geofence hold")
    fly(pilot, 6.0)
    assert pilot.vehicle.autopilot.mode is FlightMode.HOLD
    assert texts(pilot, start) == [PX4_DISTANCE_TEXT, ACTIVATED]


def test_px4s_default_battery_failsafe_only_warns_each_level_once():
    pilot = px4_in_offboard({}, stream=(0.0, 0.0, 0.0, LOCAL_NED))
    start = len(pilot.received)
    for fraction in (0.149, 0.069, 0.049):
        set_battery(pilot, fraction)
        fly(pilot, 1.0)
    fly(pilot, 6.0)
    assert pilot.vehicle.autopilot.mode is FlightMode.OFFBOARD  # COM_LOW_BAT_ACT 0: warning only
    assert texts(pilot, start) == ["Low battery\t", ACTIVATED, "Critical battery\t", ACTIVATED,
                                   "Emergency battery level\t", ACTIVATED]
    severities = [m.severity for m in pilot.received[start:] if m.get_type() == "STATUSTEXT"]
    assert severities[::2] == [mavlink.MAV_SEVERITY_CRITICAL] * 2 + [mavlink.MAV_SEVERITY_EMERGENCY]
    status = [m for m in pilot.received if m.get_type() == "BATTERY_STATUS"][-1]
    assert status.charge_state == mavlink.MAV_BATTERY_CHARGE_STATE_EMERGENCY


def test_return_at_critical_holds_first_and_the_emergency_lands_at_once():
    pilot = px4_in_offboard({"COM_LOW_BAT_ACT": 3}, stream=(0.0, 0.0, 0.0, LOCAL_NED))
    start = len(pilot.received)
    set_battery(pilot, 0.069)
    pilot.wait_for(lambda: pilot.vehicle.autopilot.mode is FlightMode.RTL, 10.0, "battery return")
    set_battery(pilot, 0.049)  # already in a failsafe worse than Hold: no second delay
    pilot.wait_for(lambda: pilot.vehicle.autopilot.mode is FlightMode.LAND, 1.0, "battery land")
    changes = mode_changes(pilot, start)
    assert [mode for _, mode in changes] == ["HOLD", "RTL", "LAND"]
    assert changes[1][0] - changes[0][0] == pytest.approx(5.0, abs=0.3) and changes[2][0] - changes[1][0] < 1.0
    assert texts(pilot, start) == ["Critical battery\t", HOLD_TEXT, ACTIVATED, "Emergency battery level\t",
                                   ACTIVATED]


def test_a_vehicle_already_landing_is_not_sent_into_return():
    pilot = px4_in_offboard({"COM_LOW_BAT_ACT": 3}, stream=(0.0, 0.0, 0.0, LOCAL_NED))
    assert pilot.command(mavlink.MAV_CMD_NAV_LAND) == ACCEPTED
    set_battery(pilot, 0.069)
    fly(pilot, 7.0)
    assert pilot.vehicle.autopilot.mode is FlightMode.LAND and HOLD_TEXT not in texts(pilot)


def test_a_switch_away_from_the_battery_return_is_kept_until_the_next_level():
    pilot = px4_in_offboard({"COM_LOW_BAT_ACT": 3, "COM_FAIL_ACT_T": 0.0}, stream=(0.0, 0.0, 0.0, LOCAL_NED))
    set_battery(pilot, 0.069)
    pilot.wait_for(lambda: pilot.vehicle.autopilot.mode is FlightMode.RTL, 2.0, "battery return")
    assert pilot.set_mode(FlightMode.OFFBOARD) == ACCEPTED  # the user takes over
    fly(pilot, 3.0)
    assert pilot.vehicle.autopilot.mode is FlightMode.OFFBOARD
    set_battery(pilot, 0.049)  # a new, worse level: a new action
    pilot.wait_for(lambda: pilot.vehicle.autopilot.mode is FlightMode.LAND, 2.0, "battery land")
