"""PX4's uploaded fences and rally points, over the in-memory link with a pymavlink client in lockstep.

A fence uploaded as the FENCE type (sitl_bridge/px4/geofence.py): its areas, the breach, and missions checked against
it; rally points uploaded as the RALLY type (sitl_bridge/px4/rally.py): stored, downloaded, cleared, and the closest
one is where RTL goes (docs/sitl.md, "PX4 missions").
"""
from __future__ import annotations

import math

from px4_mission_helpers import (ACCEPTED, FENCE, MISSION_START, RALLY, TAKEOFF, fence_item, item, rally_point, since,
                                 square, square_fence, upload)
from pymavlink.dialects.v20 import common as mavlink
from test_autopilot_fences import texts

from sitl_bridge.px4.modes import FlightMode
from sitl_bridge.scripted_flight import LockstepPilot


# ------------------------------------------------------------------ uploaded fences
def test_a_fence_upload_is_stored_downloaded_and_its_areas_are_px4s(pilot):
    ap = pilot.vehicle.autopilot
    assert upload(pilot, square_fence(pilot, no_go=(10.0, 10.0, 5.0)), mission_type=FENCE)[0] == ACCEPTED
    assert [a.inclusion for a in ap.fence_areas] == [True, False]
    assert ap.outside_fence(0.0, 0.0, 0.0) == []
    assert ap.outside_fence(0.0, 30.0, 0.0) == ["Geofence: approaching or outside geofence"]  # out of the square
    assert ap.outside_fence(11.0, 12.0, 0.0) == ["Geofence: approaching or outside geofence"]  # in the circle
    pilot.mav.mission_request_list_send(1, 1, FENCE)
    assert pilot.wait_message("MISSION_COUNT", match=lambda m: m.mission_type == FENCE).count == 5
    for seq in range(5):  # PX4 answers the expected seq only
        pilot.mav.mission_request_int_send(1, 1, seq, FENCE)
        circle = pilot.wait_message("MISSION_ITEM_INT", match=lambda m, s=seq: m.seq == s)
    pilot.mav.mission_ack_send(1, 1, ACCEPTED, FENCE)
    assert (circle.command, circle.param1, circle.mission_type) == (mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, 5.0,
                                                                    FENCE)
    assert pilot.vehicle.missions.items == []  # the mission is another list
    pilot.mav.mission_clear_all_send(1, 1, FENCE)
    assert pilot.wait_message("MISSION_ACK").type == ACCEPTED and ap.fence_areas == ()


def test_a_fence_area_without_home_is_dropped_and_a_polygon_needs_three_vertices(pilot):
    start = len(pilot.received)
    beside_home = [fence_item(pilot, seq, mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, n, e, 3)
                   for seq, (n, e) in enumerate(((50, 50), (80, 50), (80, 80)))]
    assert upload(pilot, beside_home, mission_type=FENCE)[0] == ACCEPTED
    assert "Geofence invalid, doesn't contain Home position\t" in [m.text for m in since(pilot, start, "STATUSTEXT")]
    assert pilot.vehicle.autopilot.fence_areas == ()  # an inclusion home is outside of would forbid every flight
    two = [fence_item(pilot, seq, mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, n, e, 2)
           for seq, (n, e) in enumerate(((-10, 0), (10, 0)))]
    assert upload(pilot, two, mission_type=FENCE)[0] == mavlink.MAV_MISSION_ERROR


def test_flying_out_of_an_uploaded_fence_holds_and_a_mission_crossing_it_is_refused(pilot):
    v = pilot.vehicle
    assert upload(pilot, square_fence(pilot, half_m=20.0), mission_type=FENCE)[0] == ACCEPTED
    start = len(pilot.received)
    assert upload(pilot, [item(pilot, 0, 10, 0, 10), item(pilot, 1, 10, 40, 10)])[0] == ACCEPTED
    assert "Geofence violation for waypoint 2\t" in texts(pilot, start)
    assert pilot.command(MISSION_START, 0, 0) == mavlink.MAV_RESULT_DENIED
    assert upload(pilot, [item(pilot, 0, 10, 0, 10), item(pilot, 1, 10, 15, 10)])[0] == ACCEPTED
    assert pilot.command(MISSION_START, 0, 0) == mavlink.MAV_RESULT_ACCEPTED  # inside: flown
    pilot.wait_for(lambda: v.autopilot.mission_finished, 60.0, "the mission inside the fence")
    start = len(pilot.received)
    pilot.stream = (0.0, 4.0, 0.0, mavlink.MAV_FRAME_LOCAL_NED)  # then offboard, east, out of the square
    for _ in range(3):  # a few setpoints first: PX4 enters OFFBOARD only with a live stream
        pilot.step()
    assert pilot.set_mode(FlightMode.OFFBOARD) == mavlink.MAV_RESULT_ACCEPTED
    pilot.wait_for(lambda: v.autopilot.mode is FlightMode.HOLD, 30.0, "the fence's Hold")
    assert "Geofence: approaching or outside geofence" in texts(pilot, start)
    assert 20.0 <= v.state.east_m < 23.0  # caught at the fence (checked every 200 ms at 4 m/s)


# ------------------------------------------------------------------ rally points
def test_rally_points_are_stored_downloaded_and_cleared_apart_from_the_mission(pilot):
    ap, stored = pilot.vehicle.autopilot, pilot.vehicle.missions
    assert upload(pilot, square(pilot))[0] == ACCEPTED
    points = [rally_point(pilot, 0, 80.0, 0.0), rally_point(pilot, 1, 0.0, -60.0, 20.0, mavlink.MAV_FRAME_GLOBAL)]
    result, requests = upload(pilot, points, mission_type=RALLY)
    assert result == ACCEPTED and [(r.seq, r.mission_type) for r in requests] == [(0, RALLY), (1, RALLY)]
    assert len(ap.rally_points) == 2 and len(stored.items) == 3  # the mission is another list
    pilot.mav.mission_request_list_send(1, 1, RALLY)
    assert pilot.wait_message("MISSION_COUNT", match=lambda m: m.mission_type == RALLY).count == 2
    got = []
    for seq in range(2):
        pilot.mav.mission_request_int_send(1, 1, seq, RALLY)
        got.append(pilot.wait_message("MISSION_ITEM_INT", match=lambda m, s=seq: m.seq == s))
    pilot.mav.mission_ack_send(1, 1, ACCEPTED, RALLY)
    assert [(m.command, m.frame, m.x, m.y, m.z, m.mission_type) for m in got] == [
        (mavlink.MAV_CMD_NAV_RALLY_POINT, frame, sent.x, sent.y, sent.z, RALLY)
        for sent, frame in zip(points, (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mavlink.MAV_FRAME_GLOBAL_INT))]
    assert {(m.param1, m.param2, m.param3, m.param4) for m in got} == {(0.0, 0.0, 0.0, 0.0)}  # as PX4 formats them
    pilot.mav.mission_clear_all_send(1, 1, RALLY)
    assert pilot.wait_message("MISSION_ACK", match=lambda m: m.mission_type == RALLY).type == ACCEPTED
    assert ap.rally_points == () and stored.rally == [] and len(stored.items) == 3


def test_a_rally_upload_holds_32_points_and_keeps_what_px4_parses(pilot):
    too_many = [rally_point(pilot, seq, 50.0, float(seq)) for seq in range(33)]
    assert upload(pilot, too_many, mission_type=RALLY)[0] == mavlink.MAV_MISSION_NO_SPACE  # DM_KEY_SAFE_POINTS_MAX
    waypoint = item(pilot, 1, 40.0, 40.0, 10.0)
    waypoint.mission_type = RALLY
    assert upload(pilot, [rally_point(pilot, 0, 50.0, 0.0), waypoint], mission_type=RALLY)[0] == ACCEPTED
    assert len(pilot.vehicle.missions.rally) == 2 and len(pilot.vehicle.autopilot.rally_points) == 1  # RTL: rally only
    local = rally_point(pilot, 0, 50.0, 0.0, frame=mavlink.MAV_FRAME_LOCAL_NED)
    assert upload(pilot, [local], mission_type=RALLY)[0] == mavlink.MAV_MISSION_UNSUPPORTED_FRAME
    assert len(pilot.vehicle.missions.rally) == 2  # a refused upload keeps what was stored


def return_from(pilot: LockstepPilot, north: float, east: float, alt: float = 15.0) -> None:
    """Take off, fly to (north, east) at ``alt`` with DO_REPOSITION, then RTL until landed and disarmed."""
    v = pilot.vehicle
    pilot.set_param("MIS_TAKEOFF_ALT", alt)
    assert pilot.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_ACCEPTED
    assert pilot.command(TAKEOFF, *[math.nan] * 7) == mavlink.MAV_RESULT_ACCEPTED
    pilot.wait_for(lambda: v.autopilot.mode is FlightMode.HOLD and not v.state.on_ground, 30.0, "takeoff")
    lat, lon, _ = v.frame.to_geodetic(north, east, 0.0)
    assert pilot.command(mavlink.MAV_CMD_DO_REPOSITION, -1, 1, 0, math.nan, lat, lon,
                         v.home.alt_m + alt) == mavlink.MAV_RESULT_ACCEPTED
    pilot.wait_for(lambda: math.hypot(v.state.north_m - north, v.state.east_m - east) < 1.0, 60.0, "out there")
    assert pilot.command(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH) == mavlink.MAV_RESULT_ACCEPTED
    pilot.wait_for(lambda: not v.autopilot.armed, 120.0, "landed and disarmed")


def test_rtl_lands_at_the_closest_rally_point_when_it_is_closer_than_home(pilot):
    """rtl.cpp with RTL_TYPE 0: the nearest of home and the rally points, a rally point within 10 m of home not
    counting, one whose frame is MAV_FRAME_GLOBAL_RELATIVE_ALT_INT read as GLOBAL_RELATIVE_ALT."""
    v = pilot.vehicle
    points = [rally_point(pilot, 0, 5.0, 5.0), rally_point(pilot, 1, 70.0, 10.0),
              rally_point(pilot, 2, 60.0, 80.0, frame=mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)]
    assert upload(pilot, points, mission_type=RALLY)[0] == ACCEPTED
    return_from(pilot, 60.0, 50.0)
    assert math.hypot(v.state.north_m - 60.0, v.state.east_m - 80.0) < 1.5  # 30 m away, not the other at 41 m
    assert v.state.on_ground and v.autopilot.rtl_destination is not None


def test_rtl_goes_home_when_home_is_closer_than_every_rally_point(pilot):
    v = pilot.vehicle
    assert upload(pilot, [rally_point(pilot, 0, 8.0, 0.0), rally_point(pilot, 1, -60.0, 0.0)],
                  mission_type=RALLY)[0] == ACCEPTED
    return_from(pilot, 25.0, 0.0)  # home 25 m away; the point 8 m from home is too close to home to count
    assert math.hypot(v.state.north_m, v.state.east_m) < 1.5 and v.autopilot.rtl_destination is None
