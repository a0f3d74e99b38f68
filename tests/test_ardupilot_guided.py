"""The ArduPilot Copter personality in GUIDED, flown by pymavlink over the in-memory link in lockstep.

Each test states what ArduCopter does (its source is cited in docs/sitl.md) and checks the simulated vehicle does the
same: velocity setpoints and GUID_TIMEOUT, clamping and the body frame, position targets, DO_REPOSITION, global position
targets, setpoints outside GUIDED, and GUIDED mode waypoints.
"""
from __future__ import annotations

import math

import pytest
from ardupilot_helpers import ACCEPTED, BODY_NED, DENIED, LOCAL_NED, POSITION, VELOCITY, airborne, fly, texts
from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.ardupilot.modes import CopterMode
from sitl_bridge.scripted_flight import LockstepPilot


# ---------------------------------------------------------------- GUIDED setpoints and GUID_TIMEOUT
@pytest.mark.parametrize("timeout_s", [3.0, 1.0])
def test_guided_velocity_stops_after_guid_timeout_and_stays_guided(timeout_s):
    pilot = airborne({"GUID_TIMEOUT": timeout_s})
    pilot.stream = (4.0, 0.0, 0.0, LOCAL_NED)
    fly(pilot, 5.0)
    pilot.stream = None
    last_sent = pilot.vehicle.autopilot.setpoint.time_s
    fly(pilot, timeout_s - 0.2)
    assert pilot.vehicle.ground_velocity[0] == pytest.approx(4.0, abs=0.2)  # still flying the last velocity
    pilot.wait_for(lambda: pilot.vehicle.autopilot.guided_timed_out, 1.0, "GUID_TIMEOUT")
    assert pilot.vehicle.time_s - last_sent == pytest.approx(timeout_s, abs=0.02)
    fly(pilot, 4.0)
    assert math.hypot(*pilot.vehicle.ground_velocity[:2]) < 0.3
    assert pilot.vehicle.autopilot.mode is CopterMode.GUIDED and pilot.heartbeat_mode() is CopterMode.GUIDED
    assert not any("Failsafe" in t for t in texts(pilot))  # a stop, not a failsafe


def test_guided_velocity_is_clamped_and_body_frame_rotated():
    pilot = airborne()
    pilot.stream = (30.0, 0.0, 0.0, LOCAL_NED)
    fly(pilot, 6.0)
    assert pilot.vehicle.ground_velocity[0] == pytest.approx(10.0, abs=0.3)  # WPNAV_SPEED 1000 cm/s
    pilot.stream = None
    for _ in range(60):  # face east, stopped
        pilot.mav.set_position_target_local_ned_send(0, 1, 1, LOCAL_NED, 2503, 0, 0, 0, 0, 0, 0, 0, 0, 0,
                                                     math.pi / 2, 0)
        fly(pilot, 0.1)
    pilot.stream = (3.0, 0.0, 0.0, BODY_NED)
    fly(pilot, 4.0)
    vn, ve, _ = pilot.vehicle.ground_velocity
    assert ve == pytest.approx(3.0, abs=0.3) and abs(vn) < 0.3


def test_position_target_is_held_past_guid_timeout():
    pilot = airborne()
    pilot.mav.set_position_target_local_ned_send(0, 1, 1, LOCAL_NED, POSITION, 25.0, -10.0, -12.0,
                                                 0, 0, 0, 0, 0, 0, 0, 0)
    fly(pilot, 20.0)
    s = pilot.vehicle.state
    assert (s.north_m, s.east_m, s.down_m) == pytest.approx((25.0, -10.0, -12.0), abs=0.4)


def reposition(pilot: LockstepPilot, flags: int, x: int, y: int, z: float,
               frame: int = mavlink.MAV_FRAME_GLOBAL_INT) -> int:
    pilot.mav.command_int_send(1, 1, frame, mavlink.MAV_CMD_DO_REPOSITION, 0, 0, -1, flags, 0, math.nan, x, y, z)
    return pilot.wait_message("COMMAND_ACK", 0.5, lambda m: m.command == mavlink.MAV_CMD_DO_REPOSITION).result


def test_do_reposition_is_a_guided_position_target_as_arducopter_makes_it():
    # GCS_MAVLINK_Copter::handle_command_int_do_reposition (docs/sitl.md): MAVSDK's goto_location on ArduPilot.
    pilot = airborne()
    vehicle = pilot.vehicle
    lat, lon, _ = vehicle.frame.to_geodetic(40.0, 30.0, 0.0)
    x, y = int(round(lat * 1e7)), int(round(lon * 1e7))
    assert pilot.set_mode(CopterMode.LOITER) == ACCEPTED
    assert reposition(pilot, 0, x, y, 15.0, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT) == DENIED  # no flag
    assert vehicle.autopilot.mode is CopterMode.LOITER
    assert reposition(pilot, 1, 0, 0, 15.0) == DENIED  # Location::sanitize: no position
    for zero in (0.0, 0.009, -0.009):  # Location::sanitize: 0 cm above home means "this altitude": refused
        assert reposition(pilot, 1, x, y, zero, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT) == DENIED
    assert reposition(pilot, 1, x, y, 15.0, mavlink.MAV_FRAME_LOCAL_NED) == DENIED  # not a global frame
    assert reposition(pilot, 1, x, y, 15.0, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT) == ACCEPTED
    assert vehicle.autopilot.mode is CopterMode.GUIDED
    fly(pilot, 30.0)
    s = vehicle.state
    assert (s.north_m, s.east_m, -s.down_m) == pytest.approx((40.0, 30.0, 15.0), abs=0.5)
    # In GUIDED no flag is needed; z in MAV_FRAME_GLOBAL_INT is AMSL. COMMAND_LONG is not ArduCopter's way.
    assert reposition(pilot, 0, x, y, vehicle.config.home.alt_m + 8.0) == ACCEPTED
    fly(pilot, 15.0)
    assert -vehicle.state.down_m == pytest.approx(8.0, abs=0.4)
    assert pilot.command(mavlink.MAV_CMD_DO_REPOSITION, -1, 1, 0, 0, lat, lon, 20.0) == mavlink.MAV_RESULT_UNSUPPORTED


def test_setpoints_outside_guided_are_ignored_and_invalid_ones_stop_the_vehicle():
    pilot = airborne()
    pilot.stream = (5.0, 0.0, 0.0, LOCAL_NED)
    fly(pilot, 4.0)
    pilot.stream = None
    pilot.mav.set_position_target_local_ned_send(0, 1, 1, mavlink.MAV_FRAME_GLOBAL, VELOCITY, 0, 0, 0,
                                                 5.0, 0, 0, 0, 0, 0, 0, 0)
    fly(pilot, 4.0)
    assert pilot.vehicle.autopilot.setpoints_ignored["frame 0"] == 1
    assert math.hypot(*pilot.vehicle.ground_velocity[:2]) < 0.3  # ModeGuided::init: stop
    pilot.set_mode(CopterMode.LOITER)
    pilot.send_velocity(5.0, 0.0, 0.0)
    fly(pilot, 1.0)
    assert pilot.vehicle.autopilot.setpoints_ignored["not in GUIDED"] == 1



def global_setpoint(pilot: LockstepPilot, frame: int, mask: int, lat: float, lon: float, alt: float,
                    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
    pilot.mav.set_position_target_global_int_send(0, 1, 1, frame, mask, int(round(lat * 1e7)), int(round(lon * 1e7)),
                                                  alt, *velocity, 0, 0, 0, 0, 0)


def test_global_position_targets_are_flown_in_guided_as_arducopter_takes_them():
    # GCS_MAVLINK_Copter::handle_message_set_position_target_global_int (docs/sitl.md): GUIDED only; the GLOBAL
    # frames' altitude is AMSL, the GLOBAL_RELATIVE_ALT ones' above home; a bad latitude or a terrain frame (no
    # terrain data) stops the vehicle.
    pilot = airborne()
    vehicle, home_alt = pilot.vehicle, pilot.vehicle.config.home.alt_m
    lat, lon, _ = vehicle.frame.to_geodetic(30.0, -20.0, 0.0)
    global_setpoint(pilot, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, POSITION, lat, lon, 15.0)
    fly(pilot, 25.0)
    s = vehicle.state
    assert (s.north_m, s.east_m, -s.down_m) == pytest.approx((30.0, -20.0, 15.0), abs=0.5)
    global_setpoint(pilot, mavlink.MAV_FRAME_GLOBAL, POSITION, lat, lon, home_alt + 8.0)  # the float frame too
    fly(pilot, 10.0)
    assert -vehicle.state.down_m == pytest.approx(8.0, abs=0.4)
    global_setpoint(pilot, mavlink.MAV_FRAME_GLOBAL_INT, VELOCITY, 0.0, 0.0, 0.0, (4.0, 0.0, 0.0))
    fly(pilot, 3.0)
    assert vehicle.ground_velocity[0] == pytest.approx(4.0, abs=0.3)
    for frame, lat_deg, reason in ((mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT, lat, "terrain frame (no terrain data)"),
                                   (mavlink.MAV_FRAME_GLOBAL_INT, 91.0, "latitude/longitude out of range"),
                                   (mavlink.MAV_FRAME_LOCAL_NED, lat, "frame 1")):
        global_setpoint(pilot, mavlink.MAV_FRAME_GLOBAL_INT, VELOCITY, 0.0, 0.0, 0.0, (4.0, 0.0, 0.0))
        fly(pilot, 2.0)
        global_setpoint(pilot, frame, POSITION, lat_deg, lon, 15.0)
        fly(pilot, 4.0)
        assert vehicle.autopilot.setpoints_ignored[reason] == 1, reason
        assert math.hypot(*vehicle.ground_velocity[:2]) < 0.3, reason  # ModeGuided::init: stop
    pilot.set_mode(CopterMode.LOITER)
    global_setpoint(pilot, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, POSITION, lat, lon, 15.0)
    pilot.vehicle.run(0.5)
    assert vehicle.autopilot.setpoints_ignored["not in GUIDED"] == 1


def guided_item(pilot: LockstepPilot, current: int, frame: int, lat: float, lon: float, alt: float,
                command: int = mavlink.MAV_CMD_NAV_WAYPOINT, as_int: bool = True) -> int:
    """A MISSION_ITEM(_INT) outside an upload; returns the MISSION_ACK's result."""
    if as_int:
        pilot.mav.mission_item_int_send(1, 1, 0, frame, command, current, 0, 0, 0, 0, 0,
                                        int(round(lat * 1e7)), int(round(lon * 1e7)), alt)
    else:  # DroneKit's simple_goto: MISSION_ITEM, degrees as floats
        pilot.mav.mission_item_send(1, 1, 0, frame, command, current, 0, 0, 0, 0, 0, lat, lon, alt)
    return pilot.wait_message("MISSION_ACK", 0.5).type


def test_guided_mode_waypoints_as_arducopter_takes_them():
    # GCS_MAVLINK::handle_mission_item, current == 2 → ModeAuto::do_guided (docs/sitl.md).
    pilot = airborne()
    vehicle = pilot.vehicle
    lat, lon, _ = vehicle.frame.to_geodetic(-25.0, 30.0, 0.0)
    relative = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT
    assert guided_item(pilot, 2, relative, lat, lon, 14.0, as_int=False) == mavlink.MAV_MISSION_ACCEPTED
    fly(pilot, 20.0)
    s = vehicle.state
    assert (s.north_m, s.east_m, -s.down_m) == pytest.approx((-25.0, 30.0, 14.0), abs=0.5)
    assert guided_item(pilot, 3, relative, lat, lon, 30.0) == mavlink.MAV_MISSION_ACCEPTED  # Copter: nothing
    fly(pilot, 5.0)
    assert -vehicle.state.down_m == pytest.approx(14.0, abs=0.3)
    assert guided_item(pilot, 2, relative, 91.0, lon, 14.0) == mavlink.MAV_MISSION_INVALID_PARAM5_X
    assert guided_item(pilot, 2, relative, lat, lon, math.nan) == mavlink.MAV_MISSION_INVALID_PARAM7
    home_alt = vehicle.config.home.alt_m  # MAV_FRAME_MISSION: AP_Mission reads the altitude as AMSL
    assert guided_item(pilot, 2, mavlink.MAV_FRAME_MISSION, lat, lon, home_alt + 9.0) == mavlink.MAV_MISSION_ACCEPTED
    fly(pilot, 10.0)
    assert -vehicle.state.down_m == pytest.approx(9.0, abs=0.3)
    assert guided_item(pilot, 2, mavlink.MAV_FRAME_LOCAL_NED, lat, lon, 14.0) == mavlink.MAV_MISSION_UNSUPPORTED_FRAME
    assert guided_item(pilot, 0, relative, lat, lon, 14.0) == mavlink.MAV_MISSION_ERROR  # no upload under way
    assert pilot.set_mode(CopterMode.LOITER) == ACCEPTED
    assert guided_item(pilot, 2, relative, lat, lon, 20.0) == mavlink.MAV_MISSION_ERROR  # do_guided: GUIDED only
