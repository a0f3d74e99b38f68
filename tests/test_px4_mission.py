"""PX4's mission protocol, Mission mode, uploaded fences and rally points, over the in-memory link with a pymavlink
client in lockstep.

What PX4 does is in sitl_bridge/px4/mission_protocol.py and sitl_bridge/px4/mission.py (docs/sitl.md, "PX4 missions",
has the source lines): the upload handshake and its retries, the download, clear and set-current, the feasibility
check (a mission outside the geofence is stored but cannot be started), the climb PX4 inserts before the first
waypoint, hold times, the landing item, pausing and resuming, and the restart after a finished mission; a fence
uploaded as the FENCE type (sitl_bridge/px4/geofence.py): its areas, the breach, and missions checked against it;
rally points uploaded as the RALLY type (sitl_bridge/px4/rally.py): stored, downloaded, cleared, and the closest one
is where RTL goes.
"""
from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink
from test_autopilot_fences import texts

from sitl_bridge.px4.modes import FlightMode
from sitl_bridge.scripted_flight import LockstepPilot

ACCEPTED = mavlink.MAV_MISSION_ACCEPTED
MISSION_START = mavlink.MAV_CMD_MISSION_START
WAYPOINT, LAND, TAKEOFF = mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_LAND, mavlink.MAV_CMD_NAV_TAKEOFF
RELATIVE = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT


def item(pilot: LockstepPilot, seq: int, north: float, east: float, alt: float, command: int = WAYPOINT,
         hold_s: float = 0.0, radius_m: float = 2.0, frame: int = RELATIVE) -> mavlink.MAVLink_message:
    lat, lon, _ = pilot.vehicle.frame.to_geodetic(north, east, 0.0)
    return mavlink.MAVLink_mission_item_int_message(1, 1, seq, frame, command, int(seq == 0), 1, hold_s, radius_m,
                                                    0.0, math.nan, round(lat * 1e7), round(lon * 1e7), alt)


def since(pilot: LockstepPilot, start: int, kind: str) -> list:
    return [m for m in pilot.received[start:] if m.get_type() == kind]


def upload(pilot: LockstepPilot, items: list, mission_type: int = 0) -> tuple[int, list]:
    """MISSION_COUNT, then each requested item: the final MISSION_ACK's type and the requests seen."""
    start = len(pilot.received)
    pilot.mav.mission_count_send(1, 1, len(items), mission_type)
    requests: list = []
    for _ in range(400):
        pilot.step()
        for m in pilot.received[start:]:
            if m.get_type() == "MISSION_ACK":
                return m.type, requests
            if m.get_type() in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
                requests.append(m)
                pilot.mav.send(items[m.seq])
        start = len(pilot.received)
    raise AssertionError("no MISSION_ACK")


def square(pilot: LockstepPilot, alt: float = 15.0) -> list:
    return [item(pilot, 0, 30.0, 0.0, alt), item(pilot, 1, 30.0, 30.0, alt), item(pilot, 2, 0.0, 30.0, alt)]


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


# ------------------------------------------------------------------ uploaded fences
FENCE = mavlink.MAV_MISSION_TYPE_FENCE


def fence_item(pilot: LockstepPilot, seq: int, command: int, north: float, east: float,
               param1: float) -> mavlink.MAVLink_message:
    lat, lon, _ = pilot.vehicle.frame.to_geodetic(north, east, 0.0)
    return mavlink.MAVLink_mission_item_int_message(1, 1, seq, mavlink.MAV_FRAME_GLOBAL_INT, command, int(seq == 0),
                                                    0, param1, 0, 0, 0, round(lat * 1e7), round(lon * 1e7), 0.0,
                                                    FENCE)


def square_fence(pilot: LockstepPilot, half_m: float = 25.0, no_go: tuple[float, float, float] | None = None) -> list:
    """An inclusion square of side 2 x half_m around home, and optionally an exclusion circle (north, east, r)."""
    corners = ((-half_m, -half_m), (half_m, -half_m), (half_m, half_m), (-half_m, half_m))
    inclusion = mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
    items = [fence_item(pilot, seq, inclusion, n, e, 4) for seq, (n, e) in enumerate(corners)]
    if no_go:
        items.append(fence_item(pilot, 4, mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, no_go[0], no_go[1], no_go[2]))
    return items


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
RALLY = mavlink.MAV_MISSION_TYPE_RALLY


def rally_point(pilot: LockstepPilot, seq: int, north: float, east: float, alt: float = 10.0,
                frame: int = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT) -> mavlink.MAVLink_message:
    """A rally point as QGroundControl sends one (MISSION_ITEM_INT, MAV_FRAME_GLOBAL_RELATIVE_ALT, no parameters)."""
    lat, lon, _ = pilot.vehicle.frame.to_geodetic(north, east, 0.0)
    return mavlink.MAVLink_mission_item_int_message(1, 1, seq, frame, mavlink.MAV_CMD_NAV_RALLY_POINT, 0, 0, 1, 2, 3,
                                                    4, round(lat * 1e7), round(lon * 1e7), alt, RALLY)


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
