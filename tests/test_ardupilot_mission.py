"""ArduCopter's mission protocol and AUTO mode, its fence and rally uploads, over the in-memory link with a pymavlink
client in lockstep.

What ArduPilot does is in sitl_bridge/ardupilot/mission_protocol.py and sitl_bridge/ardupilot/auto.py (docs/sitl.md,
"ArduPilot missions"): item 0 is home, uploads are answered with MISSION_REQUEST, a second a request, 8 s to give
up; AUTO is not armable, needs a takeoff first when armed on the ground, takes off on MISSION_START, announces each
command, holds at the end in the air, and disarms after a LAND. The FENCE type (sitl_bridge/ardupilot/
fence_protocol.py) is validated as a whole when the last item arrives; the RALLY type (sitl_bridge/ardupilot/
rally.py) is written point by point, and RTL goes to the closest rally point as AP_Rally chooses it.
"""
from __future__ import annotations

import math

import pytest
from ardupilot_helpers import ACCEPTED, ARM, FAILED, airborne, copter, texts
from px4_mission_helpers import fence_item, rally_point, square_fence, upload  # the same client side
from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.ardupilot.modes import CopterMode
from sitl_bridge.scripted_flight import LockstepPilot

RELATIVE = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
MISSION_START = mavlink.MAV_CMD_MISSION_START
WAYPOINT, TAKEOFF, LAND, RTL = (mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_TAKEOFF, mavlink.MAV_CMD_NAV_LAND,
                                mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH)


def item(pilot: LockstepPilot, seq: int, command: int, north: float = 0.0, east: float = 0.0, alt: float = 0.0,
         p1: float = 0.0, p2: float = 0.0, frame: int = RELATIVE) -> mavlink.MAVLink_message:
    if command in (mavlink.MAV_CMD_DO_CHANGE_SPEED, RTL):
        return mavlink.MAVLink_mission_item_int_message(1, 1, seq, mavlink.MAV_FRAME_MISSION, command, 0, 1, p1, p2,
                                                        -1 if p2 else 0, 0, 0, 0, 0)
    lat, lon, _ = pilot.vehicle.frame.to_geodetic(north, east, 0.0)
    return mavlink.MAVLink_mission_item_int_message(1, 1, seq, frame, command, 0, 1, p1, p2, 0, 0,
                                                    round(lat * 1e7), round(lon * 1e7), alt)


def home_item(pilot: LockstepPilot) -> mavlink.MAVLink_message:
    return item(pilot, 0, WAYPOINT, frame=mavlink.MAV_FRAME_GLOBAL)


def survey(pilot: LockstepPilot) -> list:
    """Home's place, takeoff to 12 m, 30 m north, 8 m/s, 30 m east with a 3 s wait, return to launch."""
    return [home_item(pilot), item(pilot, 1, TAKEOFF, alt=12.0), item(pilot, 2, WAYPOINT, 30.0, 0.0, 12.0),
            item(pilot, 3, mavlink.MAV_CMD_DO_CHANGE_SPEED, p1=1, p2=8.0),
            item(pilot, 4, WAYPOINT, 30.0, 30.0, 12.0, p1=3.0), item(pilot, 5, RTL)]


def test_upload_is_requested_with_mission_request_and_home_is_item_0_of_the_download():
    pilot = copter()
    pilot.wait_for(lambda: pilot.vehicle.autopilot.gps_ok, 3.0, "GPS")
    start = len(pilot.received)
    result, requests = upload(pilot, survey(pilot))
    assert result == mavlink.MAV_MISSION_ACCEPTED
    assert [(r.get_type(), r.seq) for r in requests] == [("MISSION_REQUEST", seq) for seq in range(6)]
    assert "Flight plan received" in texts(pilot, start)
    assert [i.command for i in pilot.vehicle.copter_missions.items] == [TAKEOFF, WAYPOINT, 178, WAYPOINT, RTL]
    pilot.mav.mission_request_list_send(1, 1, 0)
    assert pilot.wait_message("MISSION_COUNT").count == 6  # home included
    got = []
    for seq in (0, 4):
        pilot.mav.mission_request_int_send(1, 1, seq, 0)
        got.append(pilot.wait_message("MISSION_ITEM_INT", match=lambda m, s=seq: m.seq == s))
    home = pilot.vehicle.home
    assert (got[0].frame, got[0].x, got[0].y) == (mavlink.MAV_FRAME_GLOBAL, round(home.lat_deg * 1e7),
                                                  round(home.lon_deg * 1e7))
    assert abs(got[0].z - home.alt_m) < 0.01  # home's altitude above mean sea level
    assert (got[1].frame, got[1].param1, got[1].z) == (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, 3.0, 12.0)


def test_an_unanswered_upload_is_asked_again_every_second_and_cancelled_after_8_s():
    pilot = copter()
    start = len(pilot.received)
    pilot.mav.mission_count_send(1, 1, 3, 0)
    for _ in range(int(10.0 / pilot.vehicle.dt_s)):
        pilot.step()
    requests = [m for m in pilot.received[start:] if m.get_type() == "MISSION_REQUEST"]
    assert all(r.seq == 0 for r in requests) and 8 <= len(requests) <= 10
    assert "Mission upload timeout" in texts(pilot, start)
    ack = next(m for m in pilot.received[start:] if m.get_type() == "MISSION_ACK")
    assert ack.type == mavlink.MAV_MISSION_OPERATION_CANCELLED


def test_a_wrong_seq_is_refused_and_the_upload_goes_on():
    pilot = copter()
    pilot.mav.mission_count_send(1, 1, 2, 0)
    assert pilot.wait_message("MISSION_REQUEST").seq == 0
    pilot.mav.send(item(pilot, 1, WAYPOINT, 10, 0, 10))
    assert pilot.wait_message("MISSION_ACK").type == mavlink.MAV_MISSION_INVALID_SEQUENCE
    pilot.mav.send(home_item(pilot))
    pilot.mav.send(item(pilot, 1, WAYPOINT, 10, 0, 10))
    assert pilot.wait_message("MISSION_ACK", match=lambda m: m.type == mavlink.MAV_MISSION_ACCEPTED)
    assert len(pilot.vehicle.copter_missions.items) == 1


def test_auto_is_not_armable_needs_a_takeoff_and_mission_start_flies_the_mission():
    pilot = copter()
    v = pilot.vehicle
    pilot.wait_for(lambda: v.autopilot.gps_ok, 3.0, "GPS")
    assert upload(pilot, survey(pilot))[0] == mavlink.MAV_MISSION_ACCEPTED
    assert pilot.set_mode(CopterMode.AUTO) == ACCEPTED  # disarmed: any mode
    start = len(pilot.received)
    assert pilot.command(ARM, 1) == FAILED and "Arm: Mode not armable" in texts(pilot, start)
    assert pilot.set_mode(CopterMode.GUIDED) == ACCEPTED and pilot.command(ARM, 1) == ACCEPTED
    pilot.mav.request_data_stream_send(1, 1, mavlink.MAV_DATA_STREAM_EXTENDED_STATUS, 2, 1)  # as MAVProxy asks
    start = len(pilot.received)
    assert pilot.command(MISSION_START, 0, 0) == ACCEPTED  # AUTO, and the takeoff may go
    pilot.wait_for(lambda: v.autopilot.mission_state == "complete" or not v.autopilot.armed, 120.0, "the mission")
    pilot.wait_for(lambda: not v.autopilot.armed, 30.0, "disarmed at home")
    for _ in range(int(1.5 / v.dt_s)):  # the next MISSION_CURRENTs (EXT_STAT at 2 Hz)
        pilot.step()
    said = texts(pilot, start)
    assert said[:3] == ["Mission: 1 Takeoff", "Mission: 2 WP", "Mission: 3 ChangeSpeed"]
    assert "Reached command #2" in said and "Reached command #4" in said and "Mission: 5 RTL" in said
    reached = [m.seq for m in pilot.received[start:] if m.get_type() == "MISSION_ITEM_REACHED"]
    assert reached == [1, 3, 2, 4, 5]  # a DO command completes as its navigation command starts
    current = [m for m in pilot.received[start:] if m.get_type() == "MISSION_CURRENT"]
    assert {m.seq for m in current} >= {1, 2, 4, 5} and {m.total for m in current} == {5}
    assert current[0].mission_mode == 1 and current[-1].mission_state == mavlink.MISSION_STATE_COMPLETE
    assert math.hypot(v.state.north_m, v.state.east_m) < 1.5 and v.autopilot.mode is CopterMode.AUTO


def test_armed_on_the_ground_auto_refuses_a_mission_without_a_takeoff():
    pilot = copter()
    pilot.wait_for(lambda: pilot.vehicle.autopilot.gps_ok, 3.0, "GPS")
    assert upload(pilot, [home_item(pilot), item(pilot, 1, WAYPOINT, 20, 0, 10)])[0] == mavlink.MAV_MISSION_ACCEPTED
    assert pilot.set_mode(CopterMode.GUIDED) == ACCEPTED and pilot.command(ARM, 1) == ACCEPTED
    start = len(pilot.received)
    assert pilot.set_mode(CopterMode.AUTO) == FAILED
    assert texts(pilot, start) == ["Auto: Missing Takeoff Cmd", "Mode change to AUTO failed: init failed"]


def test_a_land_command_lands_there_disarms_and_the_mission_stays_on_it():
    pilot = airborne(alt_m=10.0)
    v = pilot.vehicle
    items = [home_item(pilot), item(pilot, 1, WAYPOINT, 20, 0, 10), item(pilot, 2, LAND, 20, 20, 0)]
    assert upload(pilot, items)[0] == mavlink.MAV_MISSION_ACCEPTED
    start = len(pilot.received)
    assert pilot.set_mode(CopterMode.AUTO) == ACCEPTED  # in the air: no takeoff needed
    pilot.wait_for(lambda: not v.autopilot.armed, 90.0, "landed and disarmed")
    assert math.hypot(v.state.north_m - 20.0, v.state.east_m - 20.0) < 2.5
    assert v.autopilot.nav_index is None  # disarming reset the mission's commands
    reached = [m.seq for m in pilot.received[start:] if m.get_type() == "MISSION_ITEM_REACHED"]
    assert reached == [1]  # no REACHED for the LAND command: it disarms instead
    assert "Mission: 2 Land" in texts(pilot, start)


def test_the_end_of_the_mission_in_the_air_holds_in_auto_and_clear_all_is_refused_while_it_runs():
    pilot = airborne(alt_m=10.0)
    v = pilot.vehicle
    assert upload(pilot, [home_item(pilot), item(pilot, 1, WAYPOINT, 25, 0, 10)])[0] == mavlink.MAV_MISSION_ACCEPTED
    assert pilot.set_mode(CopterMode.AUTO) == ACCEPTED
    pilot.mav.mission_clear_all_send(1, 1, 0)
    assert pilot.wait_message("MISSION_ACK").type == mavlink.MAV_MISSION_ERROR  # armed and running
    pilot.wait_for(lambda: v.autopilot.mission_state == "complete", 40.0, "the waypoint")
    fly_s = 5.0
    for _ in range(int(fly_s / v.dt_s)):
        pilot.step()
    assert v.autopilot.armed and v.autopilot.mode is CopterMode.AUTO
    assert math.hypot(v.state.north_m - 25.0, v.state.east_m) < 2.5 and abs(v.state.vn_mps) < 0.3


def test_leaving_auto_and_coming_back_flies_the_current_command_again():
    pilot = airborne(alt_m=10.0)
    v = pilot.vehicle
    items = [home_item(pilot), item(pilot, 1, WAYPOINT, 10, 0, 10), item(pilot, 2, WAYPOINT, 60, 0, 10)]
    assert upload(pilot, items)[0] == mavlink.MAV_MISSION_ACCEPTED
    assert pilot.set_mode(CopterMode.AUTO) == ACCEPTED
    pilot.wait_for(lambda: v.autopilot.nav_index == 2 and v.state.north_m > 25.0, 40.0, "on the way to 2")
    assert pilot.set_mode(CopterMode.LOITER) == ACCEPTED
    assert v.autopilot.mission_state == "stopped"
    pilot.mav.mission_set_current_send(1, 1, 1)  # not running: the next start goes from command 1
    assert pilot.wait_message("MISSION_CURRENT", match=lambda m: m.seq == 1)
    assert pilot.set_mode(CopterMode.AUTO) == ACCEPTED
    assert v.autopilot.nav_index == 1
    pilot.wait_for(lambda: v.autopilot.mission_state == "complete", 60.0, "the mission again")
    assert math.hypot(v.state.north_m - 60.0, v.state.east_m) < 2.5


# ------------------------------------------------------------------ fences and rally points
FENCE, RALLY = mavlink.MAV_MISSION_TYPE_FENCE, mavlink.MAV_MISSION_TYPE_RALLY
INCLUSION_VERTEX = mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION


def download(pilot: LockstepPilot, mission_type: int, request=None) -> list:
    """MISSION_REQUEST_LIST, then each item with MISSION_REQUEST_INT (or ``request``'s message)."""
    pilot.mav.mission_request_list_send(1, 1, mission_type)
    count = pilot.wait_message("MISSION_COUNT", match=lambda m: m.mission_type == mission_type).count
    got = []
    for seq in range(count):
        (request or pilot.mav.mission_request_int_send)(1, 1, seq, mission_type)
        got.append(pilot.wait_message(("MISSION_ITEM" if request else "MISSION_ITEM_INT"),
                                      match=lambda m, s=seq: m.seq == s))
    return got


def test_a_fence_upload_is_validated_as_a_whole_downloaded_and_cleared():
    pilot = copter()
    pilot.wait_for(lambda: pilot.vehicle.autopilot.gps_ok, 3.0, "GPS")
    stored = pilot.vehicle.copter_transfers.fence
    fence = square_fence(pilot, half_m=40.0, no_go=(10.0, 10.0, 5.0))
    result, requests = upload(pilot, fence, mission_type=FENCE)
    assert result == mavlink.MAV_MISSION_ACCEPTED
    assert [(r.get_type(), r.mission_type) for r in requests] == [("MISSION_REQUEST", FENCE)] * 5
    assert [(a.inclusion, a.centre is None) for a in pilot.vehicle.autopilot.polyfence_areas] == [
        (True, True), (False, False)]
    got = download(pilot, FENCE)
    assert [(m.command, m.frame, m.param1, m.x, m.y, m.z, m.autocontinue) for m in got] == [
        (sent.command, mavlink.MAV_FRAME_GLOBAL, sent.param1, sent.x, sent.y, 0.0, 0) for sent in fence]
    as_float = download(pilot, FENCE, request=pilot.mav.mission_request_send)
    assert as_float[0].x == pytest.approx(fence[0].x * 1e-7, abs=1e-5)  # degrees, as a float32
    start = len(pilot.received)
    triangle_of_two = [fence_item(pilot, seq, INCLUSION_VERTEX, n, e, 2) for seq, (n, e) in enumerate(((0, 9), (9, 0)))]
    assert upload(pilot, triangle_of_two, mission_type=FENCE)[0] == mavlink.MAV_MISSION_ERROR  # after the last item
    assert texts(pilot, start) == ["Invalid vertex count (2)", "Fence validation failed"]
    start = len(pilot.received)
    assert upload(pilot, square_fence(pilot)[:3], mission_type=FENCE)[0] == mavlink.MAV_MISSION_ERROR
    assert texts(pilot, start) == ["Incorrect item count", "Fence validation failed"]  # 3 of 4 vertices
    waypoint = item(pilot, 0, WAYPOINT, 10, 0, 10)
    waypoint.mission_type = FENCE
    assert upload(pilot, [waypoint], mission_type=FENCE)[0] == mavlink.MAV_MISSION_UNSUPPORTED
    assert len(stored.items) == 5  # refused uploads leave the fence as it was
    start = len(pilot.received)
    too_many = [fence_item(pilot, seq, INCLUSION_VERTEX, 0, seq, 71) for seq in range(71)]
    assert upload(pilot, too_many, mission_type=FENCE)[0] == mavlink.MAV_MISSION_NO_SPACE
    assert "Only 70 items are supported" in texts(pilot, start)  # the fence storage's bytes / 8 in SITL
    pilot.mav.mission_clear_all_send(1, 1, FENCE)
    assert pilot.wait_message("MISSION_ACK", match=lambda m: m.mission_type == FENCE).type == \
        mavlink.MAV_MISSION_ACCEPTED
    assert stored.items == [] and pilot.vehicle.autopilot.polyfence_areas == ()


def test_rally_points_are_written_one_by_one_downloaded_in_whole_metres_and_refused_as_arducopter_does():
    pilot = copter()
    pilot.wait_for(lambda: pilot.vehicle.autopilot.gps_ok, 3.0, "GPS")
    stored = pilot.vehicle.copter_transfers.rally
    points = [rally_point(pilot, 0, 100.0, 0.0, 12.7), rally_point(pilot, 1, 0.0, 80.0, 30.0, mavlink.MAV_FRAME_GLOBAL),
              rally_point(pilot, 2, -90.0, 0.0, 20.0, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)]
    start = len(pilot.received)
    assert upload(pilot, points, mission_type=RALLY)[0] == mavlink.MAV_MISSION_ACCEPTED
    assert texts(pilot, start) == []  # no "Flight plan received" for rally points
    got = download(pilot, RALLY)
    assert [(m.frame, m.z, m.x, m.y, m.param1, m.param4) for m in got] == [
        (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, 12.0, points[0].x, points[0].y, 0.0, 0.0),  # whole metres, int16
        (mavlink.MAV_FRAME_GLOBAL, 30.0, points[1].x, points[1].y, 0.0, 0.0),
        (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, 20.0, points[2].x, points[2].y, 0.0, 0.0)]
    waypoint = item(pilot, 1, WAYPOINT, 10, 0, 10)
    waypoint.mission_type = RALLY
    assert upload(pilot, [rally_point(pilot, 0, 50.0, 50.0), waypoint], mission_type=RALLY)[0] == \
        mavlink.MAV_MISSION_UNSUPPORTED
    assert [round(p.z) for p in stored.items] == [10, 30]  # MISSION_COUNT truncated to 2, point 0 replaced
    high = rally_point(pilot, 0, 50.0, 50.0, 40000.0)
    assert upload(pilot, [high], mission_type=RALLY)[0] == mavlink.MAV_MISSION_INVALID_PARAM7  # an int16 of metres
    terrain = rally_point(pilot, 0, 50.0, 50.0, frame=mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT)
    assert upload(pilot, [terrain], mission_type=RALLY)[0] == mavlink.MAV_MISSION_UNSUPPORTED_FRAME  # no terrain
    assert upload(pilot, [rally_point(pilot, seq, 50.0, seq) for seq in range(47)], mission_type=RALLY)[0] == \
        mavlink.MAV_MISSION_NO_SPACE  # 46 in SITL's rally storage
    pilot.mav.mission_count_send(1, 1, 1, 7)
    assert pilot.wait_message("MISSION_ACK").type == mavlink.MAV_MISSION_UNSUPPORTED  # no protocol for type 7
    pilot.mav.mission_clear_all_send(1, 1, RALLY)
    assert pilot.wait_message("MISSION_ACK", match=lambda m: m.mission_type == RALLY).type == \
        mavlink.MAV_MISSION_ACCEPTED
    assert stored.items == [] and pilot.vehicle.autopilot.rally_points == ()


@pytest.mark.parametrize("params, out_m, lands_at", [
    ({}, 150.0, (100.0, 0.0)),  # RALLY_INCL_HOME 1: the rally point, 50 m away, is closer than home (150 m)
    ({}, 40.0, (0.0, 0.0)),  # home, 40 m away, is closer than the rally point (60 m)
    ({"RALLY_INCL_HOME": 0}, 40.0, (100.0, 0.0)),  # home is not a choice: the closest rally point
    ({"RALLY_LIMIT_KM": 0.04}, 150.0, (0.0, 0.0)),  # the closest rally point is beyond 40 m: home
])
def test_rtl_returns_to_the_closest_rally_point_as_ap_rally_chooses_it(params, out_m, lands_at):
    pilot = airborne(params, alt_m=10.0)
    v = pilot.vehicle
    points = [rally_point(pilot, 0, 100.0, 0.0, 20.0), rally_point(pilot, 1, 0.0, 300.0, 10.0)]
    assert upload(pilot, points, mission_type=RALLY)[0] == mavlink.MAV_MISSION_ACCEPTED
    pilot.stream = (10.0, 0.0, 0.0, mavlink.MAV_FRAME_LOCAL_NED)
    pilot.wait_for(lambda: v.state.north_m > out_m, 30, "out north")
    pilot.stream = None
    assert pilot.command(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH) == ACCEPTED
    if lands_at != (0.0, 0.0):  # at least the rally point's altitude (20 m), above RTL_ALT's 15
        assert -v.autopilot.rtl_return_down_m == pytest.approx(20.0, abs=0.3)
    pilot.wait_for(lambda: not v.autopilot.armed, 120, "landed and disarmed")
    assert math.hypot(v.state.north_m - lands_at[0], v.state.east_m - lands_at[1]) < 1.5
