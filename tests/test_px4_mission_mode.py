"""PX4's Mission mode, over the in-memory link with a pymavlink client in lockstep.

What PX4 does is in sitl_bridge/px4/mission_protocol.py and sitl_bridge/px4/mission.py (docs/sitl.md, "PX4 missions",
has the source lines): the climb PX4 inserts before the first waypoint, hold times, the landing item, pausing and
resuming, the restart after a finished mission, and set-current.
"""
from __future__ import annotations

import math

import pytest
from px4_mission_helpers import ACCEPTED, LAND, MISSION_START, item, since, square, upload
from pymavlink.dialects.v20 import common as mavlink
from test_autopilot_fences import texts

from sitl_bridge.px4.modes import FlightMode


# ------------------------------------------------------------------ flying it
def test_mission_start_climbs_first_then_flies_each_waypoint_and_loiters_at_the_end(pilot):
    v = pilot.vehicle
    items = square(pilot)
    items[1] = item(pilot, 1, 30.0, 30.0, 15.0, hold_s=3.0)
    assert upload(pilot, items)[0] == ACCEPTED
    start = len(pilot.received)
    assert pilot.command(MISSION_START, 0, 0) == mavlink.MAV_RESULT_ACCEPTED
    assert v.autopilot.armed and v.autopilot.mode is FlightMode.MISSION
    pilot.wait_for(lambda: -v.state.down_m > 5.0, 10.0, "climbing")
    assert math.hypot(v.state.north_m, v.state.east_m) < 0.5  # straight up first ("Climb to 15.0 meters ...")
    assert pilot.wait_message("EXTENDED_SYS_STATE").landed_state == mavlink.MAV_LANDED_STATE_TAKEOFF
    pilot.wait_for(lambda: v.autopilot.mission_finished, 60.0, "the mission")
    reached = [m.seq for m in since(pilot, start, "MISSION_ITEM_REACHED")]
    assert sorted(set(reached)) == [0, 1, 2]  # no REACHED for the inserted climb
    at_1 = next(i for i, m in enumerate(pilot.received[start:]) if m.get_type() == "MISSION_ITEM_REACHED"
                and m.seq == 1)
    at_0 = next(i for i, m in enumerate(pilot.received[start:]) if m.get_type() == "MISSION_ITEM_REACHED"
                and m.seq == 0)
    assert at_1 > at_0
    assert "Climb to 15.0 meters above home\t" in texts(pilot, start)
    assert "Mission finished, loitering\t" in texts(pilot, start)
    assert math.hypot(v.state.north_m - 0.0, v.state.east_m - 30.0) < 2.0
    assert pilot.wait_message("MISSION_CURRENT").mission_state == mavlink.MISSION_STATE_COMPLETE
    for _ in range(int(5.0 / v.dt_s)):  # it stays in Mission mode, holding
        pilot.step()
    assert v.autopilot.mode is FlightMode.MISSION and math.hypot(v.state.north_m, v.state.east_m - 30.0) < 2.0


def test_the_hold_time_keeps_the_vehicle_at_its_waypoint(pilot):
    v = pilot.vehicle
    items = [item(pilot, 0, 20.0, 0.0, 10.0, hold_s=6.0), item(pilot, 1, 20.0, 40.0, 10.0)]
    assert upload(pilot, items)[0] == ACCEPTED
    assert pilot.command(MISSION_START, 0, 0) == mavlink.MAV_RESULT_ACCEPTED
    pilot.wait_for(lambda: v.autopilot._item_reached_s is not None, 40.0, "at waypoint 0")
    arrived = v.time_s
    assert math.hypot(v.state.north_m - 20.0, v.state.east_m) <= 2.0 and v.autopilot.mission_current == 0
    pilot.wait_for(lambda: v.autopilot.mission_current == 1, 20.0, "leaving waypoint 0")
    assert v.time_s - arrived == pytest.approx(6.0, abs=0.05)  # held for param1, then on
    assert math.hypot(v.state.north_m - 20.0, v.state.east_m) < 2.0  # still there when it moves on


def test_a_land_item_lands_at_its_point_and_the_vehicle_disarms(pilot):
    v = pilot.vehicle
    items = [item(pilot, 0, 20.0, 0.0, 12.0), item(pilot, 1, 20.0, 25.0, 0.0, command=LAND)]
    assert upload(pilot, items)[0] == ACCEPTED
    start = len(pilot.received)
    assert pilot.command(MISSION_START, 0, 0) == mavlink.MAV_RESULT_ACCEPTED
    pilot.wait_for(lambda: v.autopilot.mission_current == 1 and v.autopilot._landing, 60.0, "over the land point")
    assert -v.state.down_m > 10.0  # flew there at its altitude before descending
    assert pilot.wait_message("EXTENDED_SYS_STATE").landed_state == mavlink.MAV_LANDED_STATE_LANDING
    pilot.wait_for(lambda: not v.autopilot.armed, 60.0, "landed and disarmed")
    assert math.hypot(v.state.north_m - 20.0, v.state.east_m - 25.0) < 1.5
    assert "Mission finished, landed\t" in texts(pilot, start)


def test_pause_in_hold_resumes_at_the_same_item_and_a_finished_mission_restarts_after_disarming(pilot):
    v = pilot.vehicle
    items = [item(pilot, 0, 20.0, 0.0, 10.0), item(pilot, 1, 20.0, 60.0, 10.0), item(pilot, 2, 0, 0, 0, LAND)]
    assert upload(pilot, items)[0] == ACCEPTED
    assert pilot.command(MISSION_START, 0, 0) == mavlink.MAV_RESULT_ACCEPTED
    pilot.wait_for(lambda: v.autopilot.mission_current == 1 and v.state.east_m > 15.0, 60.0, "on the second leg")
    assert pilot.set_mode(FlightMode.HOLD) == mavlink.MAV_RESULT_ACCEPTED  # MAVSDK's pause_mission
    paused_at = (v.state.north_m, v.state.east_m)
    for _ in range(int(4.0 / v.dt_s)):
        pilot.step()
    assert math.hypot(v.state.north_m - paused_at[0], v.state.east_m - paused_at[1]) < 4.0
    assert pilot.wait_message("MISSION_CURRENT").mission_state == mavlink.MISSION_STATE_PAUSED
    assert pilot.set_mode(FlightMode.MISSION) == mavlink.MAV_RESULT_ACCEPTED
    assert v.autopilot.mission_current == 1  # resumed, not restarted
    pilot.wait_for(lambda: not v.autopilot.armed, 120.0, "landed home and disarmed")
    assert v.autopilot.mission_finished and v.autopilot.mode is FlightMode.HOLD  # disarming on the ground: Hold
    assert pilot.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_ACCEPTED
    assert pilot.set_mode(FlightMode.MISSION) == mavlink.MAV_RESULT_ACCEPTED
    assert v.autopilot.mission_current == 0 and not v.autopilot.mission_finished  # checkMissionRestart
    pilot.wait_for(lambda: v.autopilot.mission_reached == 0, 60.0, "the first waypoint again")


def test_set_current_jumps_and_mission_current_says_so(pilot):
    v = pilot.vehicle
    assert upload(pilot, square(pilot))[0] == ACCEPTED
    pilot.mav.mission_set_current_send(1, 1, 2)
    assert pilot.wait_message("MISSION_CURRENT", match=lambda m: m.seq == 2).total == 3
    assert pilot.command(MISSION_START, -1, 0) == mavlink.MAV_RESULT_ACCEPTED  # -1: from the current item
    pilot.wait_for(lambda: v.autopilot.mission_finished, 60.0, "the mission")
    assert v.autopilot.mission_reached == 2
    assert math.hypot(v.state.north_m, v.state.east_m - 30.0) < 2.5
    start = len(pilot.received)
    pilot.mav.mission_set_current_send(1, 1, 7)
    for _ in range(20):
        pilot.step()
    assert "WPM: WP CURR CMD: Not in list\t" in texts(pilot, start)
