"""PX4's mission protocol, over the in-memory link with a pymavlink client in lockstep.

What PX4 does is in sitl_bridge/px4/mission_protocol.py and sitl_bridge/px4/mission.py (docs/sitl.md, "PX4 missions",
has the source lines): the upload handshake and its retries, unsupported and float items, the download, clear all, and
the feasibility check (a mission outside the geofence is stored but cannot be started, a takeoff item below home or
after a waypoint makes it invalid).
"""
from __future__ import annotations

import math

import pytest
from px4_mission_helpers import ACCEPTED, MISSION_START, RELATIVE, TAKEOFF, WAYPOINT, item, since, square, upload
from pymavlink.dialects.v20 import common as mavlink
from test_autopilot_fences import texts

from sitl_bridge.px4.modes import FlightMode


# ------------------------------------------------------------------ the protocol
def test_upload_requests_every_item_as_int_and_acks_after_the_last(pilot):
    result, requests = upload(pilot, square(pilot))
    assert result == ACCEPTED
    assert [(r.get_type(), r.seq, r.target_system, r.target_component) for r in requests] == [
        ("MISSION_REQUEST_INT", seq, 255, 190) for seq in range(3)]
    stored = pilot.vehicle.missions.items
    assert [(i.command, i.relative, i.z) for i in stored] == [(WAYPOINT, True, 15.0)] * 3
    assert pilot.vehicle.autopilot.mission_valid


def test_an_unanswered_request_is_repeated_then_the_transfer_times_out_without_an_ack(pilot):
    start = len(pilot.received)
    pilot.mav.mission_count_send(1, 1, 2, 0)
    for _ in range(int(6.0 / pilot.vehicle.dt_s)):
        pilot.step()
    requests = since(pilot, start, "MISSION_REQUEST_INT")
    assert all(r.seq == 0 for r in requests) and 18 <= len(requests) <= 21  # every 0.25 s for 5 s
    assert since(pilot, start, "MISSION_ACK") == []
    assert "Operation timeout\t" in texts(pilot, start)
    assert pilot.vehicle.missions.transfer is None and pilot.vehicle.missions.items == []


def test_an_unsupported_item_aborts_the_upload_and_keeps_the_stored_mission(pilot):
    assert upload(pilot, square(pilot))[0] == ACCEPTED
    jump = mavlink.MAVLink_mission_item_int_message(1, 1, 1, mavlink.MAV_FRAME_MISSION, mavlink.MAV_CMD_DO_JUMP,
                                                    0, 1, 0, 1, 0, 0, 0, 0, 0)
    assert upload(pilot, [item(pilot, 0, 5, 5, 10), jump])[0] == mavlink.MAV_MISSION_UNSUPPORTED
    local_frame = item(pilot, 0, 5, 5, 10, frame=mavlink.MAV_FRAME_LOCAL_NED)
    assert upload(pilot, [local_frame])[0] == mavlink.MAV_MISSION_UNSUPPORTED_FRAME
    speed_in_global_frame = item(pilot, 0, 5, 5, 10, command=mavlink.MAV_CMD_DO_CHANGE_SPEED)
    assert upload(pilot, [speed_in_global_frame])[0] == mavlink.MAV_MISSION_UNSUPPORTED
    assert len(pilot.vehicle.missions.items) == 3  # the square is still the mission
    rally_point_in_a_mission = item(pilot, 0, 5, 5, 10, command=mavlink.MAV_CMD_NAV_RALLY_POINT)
    assert upload(pilot, [rally_point_in_a_mission])[0] == mavlink.MAV_MISSION_ERROR  # a mission holds no rally points
    waypoint_in_a_fence = item(pilot, 0, 5, 5, 10)
    waypoint_in_a_fence.mission_type = mavlink.MAV_MISSION_TYPE_FENCE
    assert upload(pilot, [waypoint_in_a_fence], mission_type=mavlink.MAV_MISSION_TYPE_FENCE)[0] == \
        mavlink.MAV_MISSION_ERROR  # a fence holds fence items only


def test_float_items_switch_the_requests_to_float_and_a_client_nack_switches_back(pilot):
    lat, lon, _ = pilot.vehicle.frame.to_geodetic(10.0, 0.0, 0.0)
    float_items = [mavlink.MAVLink_mission_item_message(1, 1, seq, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, WAYPOINT,
                                                        int(seq == 0), 1, 0, 2, 0, math.nan, lat, lon, 12.0)
                   for seq in range(2)]
    result, requests = upload(pilot, float_items)
    assert result == ACCEPTED
    assert [r.get_type() for r in requests] == ["MISSION_REQUEST_INT", "MISSION_REQUEST"]
    assert pilot.vehicle.missions.items[1].x == pytest.approx(lat, abs=2e-6)  # a float32 latitude: ~10 cm
    start = len(pilot.received)
    pilot.mav.mission_count_send(1, 1, 1, 0)  # the float mode sticks ...
    assert pilot.wait_message("MISSION_REQUEST").seq == 0
    pilot.mav.mission_ack_send(1, 1, mavlink.MAV_MISSION_UNSUPPORTED, 0)  # ... until the client refuses it
    assert pilot.wait_message("MISSION_REQUEST_INT").seq == 0
    assert since(pilot, start, "MISSION_REQUEST_INT")


def test_download_returns_the_items_and_clear_all_empties_the_mission(pilot):
    assert upload(pilot, square(pilot, alt=18.0))[0] == ACCEPTED
    pilot.mav.mission_request_list_send(1, 1, 0)
    assert pilot.wait_message("MISSION_COUNT").count == 3
    downloaded = []
    for seq in range(3):
        pilot.mav.mission_request_int_send(1, 1, seq, 0)
        downloaded.append(pilot.wait_message("MISSION_ITEM_INT", match=lambda m, s=seq: m.seq == s))
    pilot.mav.mission_ack_send(1, 1, ACCEPTED, 0)
    sent = square(pilot, alt=18.0)
    assert [(m.frame, m.command, m.current, m.x, m.y, m.z) for m in downloaded] == [
        (RELATIVE, WAYPOINT, int(m.seq == 0), m.x, m.y, 18.0) for m in sent]
    pilot.mav.mission_clear_all_send(1, 1, 0)
    assert pilot.wait_message("MISSION_ACK").type == ACCEPTED
    pilot.mav.mission_request_list_send(1, 1, 0)
    assert pilot.wait_message("MISSION_COUNT").count == 0
    start = len(pilot.received)
    for _ in range(int(2.0 / pilot.vehicle.dt_s)):
        pilot.step()
    assert since(pilot, start, "MISSION_CURRENT") == []  # no mission, no MISSION_CURRENT (docs/sitl.md)


# ------------------------------------------------------------------ feasibility
def test_a_mission_beyond_the_geofence_is_stored_but_cannot_start(pilot):
    pilot.set_param("GF_MAX_HOR_DIST", 100.0)
    start = len(pilot.received)
    result, _ = upload(pilot, [item(pilot, 0, 30, 0, 15), item(pilot, 1, 150, 0, 15)])
    assert result == ACCEPTED  # PX4 acknowledges the transfer; the navigator then marks it invalid
    assert "Geofence violation for waypoint 2\t" in texts(pilot, start)  # PX4 counts from 1
    assert not pilot.vehicle.autopilot.mission_valid
    assert pilot.wait_message("MISSION_CURRENT").mission_state == mavlink.MISSION_STATE_NO_MISSION
    assert pilot.command(MISSION_START, 0, 0) == mavlink.MAV_RESULT_DENIED
    assert "Mission start denied! No valid mission\t" in texts(pilot, start)
    assert pilot.set_mode(FlightMode.MISSION) == mavlink.MAV_RESULT_ACCEPTED  # disarmed: the switch is allowed ...
    assert pilot.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    assert not pilot.vehicle.autopilot.armed  # ... arming in it is not


def test_a_takeoff_item_below_home_or_after_a_waypoint_makes_the_mission_invalid(pilot):
    start = len(pilot.received)
    assert upload(pilot, [item(pilot, 0, 0, 0, -5.0, command=TAKEOFF), item(pilot, 1, 20, 0, 10)])[0] == ACCEPTED
    assert "Mission rejected: Takeoff altitude below home altitude!\t" in texts(pilot, start)
    start = len(pilot.received)
    assert upload(pilot, [item(pilot, 0, 20, 0, 10), item(pilot, 1, 0, 0, 10, command=TAKEOFF)])[0] == ACCEPTED
    # exactly 50 bytes: one full STATUSTEXT, which a reader joins only once another text follows
    assert "Mission rejected: takeoff not first waypoint item\t" in [m.text for m in since(pilot, start, "STATUSTEXT")]
    assert not pilot.vehicle.autopilot.mission_valid
