"""Every command's ACK, offboard rules, setpoint frames and masks, parameters: over the in-memory link.

The client is pymavlink (MAVLink 2 bytes through :class:`MemoryMavConnection`), the vehicle runs in lockstep.
"""
from __future__ import annotations

import dataclasses
import math

import pytest
from pymavlink.dialects.v20 import common as mavlink
from test_autopilot_fences import texts

from sitl_bridge.px4.modes import FlightMode
from sitl_bridge.scripted_flight import LockstepPilot

ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
TEMPORARILY_REJECTED = mavlink.MAV_RESULT_TEMPORARILY_REJECTED
DENIED = mavlink.MAV_RESULT_DENIED
UNSUPPORTED = mavlink.MAV_RESULT_UNSUPPORTED
ARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM
REPOSITION = mavlink.MAV_CMD_DO_REPOSITION


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


def statustexts(pilot: LockstepPilot) -> list[tuple[int, str]]:
    """(severity, text) of each STATUSTEXT received, chunks joined (the denial is 52 bytes: two chunks)."""
    severities = [m.severity for m in pilot.received if m.get_type() == "STATUSTEXT" and m.chunk_seq == 0]
    return list(zip(severities, texts(pilot), strict=True))


def test_arming_texts_are_px4s_and_name_a_reason_only_where_its_health_check_has_a_text(pilot):
    """Commander::arm / disarm (PX4 >= 1.14): "Armed by external command", "Disarmed by ..."; a refusal says
    "Arming denied: Resolve system health failures first", after the check's own text if it has one (the battery's
    and the geofence's legacy mavlink_log texts; no position is an event only)."""
    critical, info = mavlink.MAV_SEVERITY_CRITICAL, mavlink.MAV_SEVERITY_INFO
    denied = (critical, "Arming denied: Resolve system health failures first\t")
    autopilot = pilot.vehicle.autopilot
    autopilot.gps_ok = False
    assert pilot.command(ARM, 1) == TEMPORARILY_REJECTED and statustexts(pilot) == [denied]
    autopilot.gps_ok = True
    full = pilot.vehicle.state.battery_wh
    pilot.vehicle.state = dataclasses.replace(pilot.vehicle.state, battery_wh=0.06 * full)
    pilot.received.clear()
    assert pilot.command(ARM, 1) == TEMPORARILY_REJECTED
    assert statustexts(pilot) == [(critical, "Critical battery\t"), denied]
    pilot.vehicle.state = dataclasses.replace(pilot.vehicle.state, battery_wh=full)
    pilot.received.clear()
    assert pilot.command(ARM, 1) == ACCEPTED and pilot.command(ARM, 0) == ACCEPTED
    assert statustexts(pilot) == [(info, "Armed by external command\t"), (info, "Disarmed by external command\t")]
    pilot.received.clear()
    assert pilot.command(ARM, 1) == ACCEPTED
    pilot.vehicle.run(pilot.vehicle.params["COM_DISARM_PRFLT"] + 0.5)
    while (m := pilot.conn.recv_msg()) is not None:
        pilot.received.append(m)
    assert statustexts(pilot)[-1] == (info, "Disarmed by auto preflight disarming\t")


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
    beat = pilot.wait_message("HEARTBEAT", 0.2,
                              lambda m: FlightMode.from_custom_mode(m.custom_mode) is FlightMode.POSCTL)
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
    # mavlink_receiver.cpp handle_request_message_command: nothing sent (no such stream; no valid home) is DENIED
    assert pilot.command(mavlink.MAV_CMD_REQUEST_MESSAGE, 65000) == DENIED
    suite = type(pilot.vehicle.sensors)
    update = suite.update
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(suite, "update", lambda self, *args: (update(self, *args), setattr(self, "gps", None)))
        pilot.step()  # a receiver without a fix
        before = len(pilot.received)
        assert pilot.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HOME_POSITION) == DENIED
        assert not [m for m in pilot.received[before:] if m.get_type() == "HOME_POSITION"]
    pilot.step()  # the fix is back
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


def command_int(pilot: LockstepPilot, command: int, params: tuple[float, float, float, float], x: int, y: int,
                z: float) -> int:
    """COMMAND_INT (MAV_FRAME_GLOBAL_INT) to the autopilot; returns the ACK's MAV_RESULT."""
    pilot.mav.command_int_send(1, 1, mavlink.MAV_FRAME_GLOBAL_INT, command, 0, 0, *params, x, y, z)
    return pilot.wait_message("COMMAND_ACK", 0.5, lambda m: m.command == command).result


def scaled(degrees: float) -> int:
    return int(round(degrees * 1e7))


def test_do_reposition_flies_to_the_point_and_holds_there_as_px4_does(pilot):
    # MAVSDK's goto_location: COMMAND_INT DO_REPOSITION, lat/lon * 1e7, AMSL altitude, param2 = the change-mode
    # flag, param4 the heading in radians (Commander::handle_command, navigator_main.cpp; docs/sitl.md).
    vehicle, home_alt = airborne(pilot).vehicle, pilot.vehicle.config.home.alt_m
    lat, lon, _ = vehicle.frame.to_geodetic(60.0, -80.0, 0.0)  # 100 m away
    before = vehicle.autopilot.hold_target
    for flags in (0, 3):  # no change-mode flag, or an unknown bit: Commander refuses, nothing changes
        assert command_int(pilot, REPOSITION, (-1, flags, 0, math.nan), scaled(lat), scaled(lon),
                           home_alt + 25) == UNSUPPORTED
    assert vehicle.autopilot.hold_target == before
    assert command_int(pilot, REPOSITION, (-1, 1, 0, math.radians(90.0)), scaled(lat), scaled(lon),
                       home_alt + 25) == ACCEPTED
    top_speed = 0.0

    def arrived() -> bool:
        nonlocal top_speed
        state = vehicle.state
        top_speed = max(top_speed, math.hypot(state.vn_mps, state.ve_mps))
        return math.hypot(state.north_m - 60.0, state.east_m + 80.0) < 1.0 and abs(-state.down_m - 25.0) < 0.5

    took = pilot.wait_for(arrived, 60.0, "the reposition point")
    assert vehicle.autopilot.mode is FlightMode.HOLD
    assert top_speed == pytest.approx(vehicle.params["MPC_XY_CRUISE"], abs=0.3) and took > 100.0 / top_speed
    assert math.degrees(vehicle.state.yaw_rad) == pytest.approx(90.0, abs=2.0)
    pilot.vehicle.run(5.0)  # and holds there
    assert math.hypot(vehicle.state.north_m - 60.0, vehicle.state.east_m + 80.0) < 1.0

    # COMMAND_LONG: degrees as floats; param1 a ground speed; no altitude (NaN): the current one is kept.
    lat, lon, _ = vehicle.frame.to_geodetic(60.0, -20.0, 0.0)
    assert pilot.command(REPOSITION, 2.0, 1, 0, math.nan, lat, lon, math.nan) == ACCEPTED
    pilot.vehicle.run(10.0)
    assert math.hypot(vehicle.state.vn_mps, vehicle.state.ve_mps) == pytest.approx(2.0, abs=0.1)
    assert -vehicle.state.down_m == pytest.approx(25.0, abs=0.5)
    # No position (x = y = INT32_MAX): an altitude change where the vehicle is.
    assert command_int(pilot, REPOSITION, (-1, 1, 0, math.nan), 2**31 - 1, 2**31 - 1, home_alt + 15) == ACCEPTED
    north, east = vehicle.state.north_m, vehicle.state.east_m
    pilot.wait_for(lambda: abs(-vehicle.state.down_m - 15.0) < 0.3, 30.0, "15 m")
    assert math.hypot(vehicle.state.north_m - north, vehicle.state.east_m - east) < 2.0


def test_do_reposition_on_the_ground_only_switches_to_hold(pilot):
    vehicle, home_alt = pilot.vehicle, pilot.vehicle.config.home.alt_m
    lat, lon, _ = vehicle.frame.to_geodetic(50.0, 0.0, 0.0)
    assert pilot.command(mavlink.MAV_CMD_NAV_LAND) == ACCEPTED
    assert command_int(pilot, REPOSITION, (-1, 1, 0, math.nan), scaled(lat), scaled(lon), home_alt + 20) == ACCEPTED
    assert vehicle.autopilot.mode is FlightMode.HOLD  # Commander switched; Navigator ignores it disarmed
    assert pilot.command(ARM, 1) == ACCEPTED
    assert command_int(pilot, REPOSITION, (-1, 1, 0, math.nan), scaled(lat), scaled(lon), home_alt + 20) == ACCEPTED
    pilot.vehicle.run(3.0)
    assert vehicle.state.on_ground and vehicle.state.north_m == pytest.approx(0.0, abs=0.5)
    # A NaN sent as an int in x and y: DENIED by mavlink_receiver.cpp before any of it; and a place off the globe.
    assert command_int(pilot, REPOSITION, (-1, 1, 0, math.nan), 0x7FF80000, 0x7FF80000, home_alt) == DENIED
    assert pilot.command(REPOSITION, -1, 1, 0, math.nan, 91.0, lon, home_alt) == DENIED


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


# ---------------------------------------------------------------- Orbit (MAV_CMD_DO_ORBIT, sitl_bridge/px4/orbit.py)
ORBIT = mavlink.MAV_CMD_DO_ORBIT


def circle_samples(pilot: LockstepPilot, centre: tuple[float, float], seconds: float) -> list[tuple[float, ...]]:
    """(distance from the centre, bearing from it (rad), ground speed, altitude, heading error to the centre (deg))
    every 0.5 s."""
    vehicle, samples = pilot.vehicle, []
    for _ in range(int(seconds / 0.5)):
        pilot.vehicle.run(0.5)
        s = vehicle.state
        dn, de = s.north_m - centre[0], s.east_m - centre[1]
        to_centre = math.degrees(math.remainder(math.atan2(-de, -dn) - s.yaw_rad, math.tau))
        samples.append((math.hypot(dn, de), math.atan2(de, dn), math.hypot(s.vn_mps, s.ve_mps), -s.down_m,
                        to_centre))
    return samples


def test_do_orbit_circles_the_point_at_its_speed_facing_the_centre_as_px4_does(pilot):
    # MAVSDK's do_orbit: COMMAND_INT, radius (sign = direction, positive clockwise), speed, yaw behaviour 0 (face
    # the centre), the centre's lat/lon * 1e7 and AMSL altitude (FlightTaskOrbit; docs/sitl.md).
    vehicle, home_alt = airborne(pilot).vehicle, pilot.vehicle.config.home.alt_m
    lat, lon, _ = vehicle.frame.to_geodetic(40.0, 0.0, 0.0)
    assert command_int(pilot, ORBIT, (20.0, 4.0, 0, math.nan), scaled(lat), scaled(lon), home_alt + 15) == ACCEPTED
    assert vehicle.autopilot.mode is FlightMode.ORBIT and vehicle.autopilot.status.phase == "holding"
    heartbeat = pilot.wait_message("HEARTBEAT", 1.5)
    assert (heartbeat.custom_mode >> 16 & 0xFF, heartbeat.custom_mode >> 24) == (3, 1)  # POSCTL main, ORBIT sub
    assert heartbeat.base_mode & mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
    pilot.wait_for(lambda: vehicle.autopilot.orbit.on_circle(vehicle.state), 30.0, "on the circle")
    pilot.vehicle.run(3.0)  # up to speed
    samples = circle_samples(pilot, (40.0, 0.0), 10.0)
    assert all(19.7 < d < 20.3 and speed == pytest.approx(4.0, abs=0.2) and alt == pytest.approx(15.0, abs=0.3)
               and abs(yaw_error) < 3.0 for d, _, speed, alt, yaw_error in samples)
    turned = sum(math.remainder(b - a, math.tau) for (_, a, *_), (_, b, *_) in zip(samples, samples[1:]))
    assert math.degrees(turned) == pytest.approx(math.degrees(4.0 / 20.0 * 9.5), abs=8.0)  # clockwise: bearing grows


def test_do_orbit_direction_speed_limit_radius_limit_and_the_ground(pilot):
    vehicle = airborne(pilot).vehicle
    # No centre or altitude (NaN): around where the vehicle is, at its altitude. Negative radius: counter-clockwise;
    # 10 m/s on 5 m is more than PX4's 2 m/s² of centripetal acceleration allows: sqrt(2 * 5) m/s.
    centre = (vehicle.state.north_m, vehicle.state.east_m)
    assert pilot.command(ORBIT, -5.0, 10.0, 0, math.nan, math.nan, math.nan, math.nan) == ACCEPTED
    altitude = -vehicle.state.down_m
    pilot.wait_for(lambda: vehicle.autopilot.orbit.on_circle(vehicle.state), 30.0, "on the circle")
    pilot.vehicle.run(3.0)
    samples = circle_samples(pilot, centre, 4.0)
    assert all(4.8 < d < 5.2 and speed == pytest.approx(math.sqrt(10.0), abs=0.2)
               and alt == pytest.approx(altitude, abs=0.3) for d, _, speed, alt, _ in samples)
    assert sum(math.remainder(b - a, math.tau) for (_, a, *_), (_, b, *_) in zip(samples, samples[1:])) < -1.0
    # A radius beyond MC_ORBIT_RAD_MAX: "Orbit radius limit exceeded", the mode stays, the vehicle holds.
    since = len(pilot.received)
    assert pilot.command(ORBIT, 2000.0, 3.0, 0, math.nan, math.nan, math.nan, math.nan) == ACCEPTED
    pilot.vehicle.run(3.0)
    held = vehicle.state
    pilot.vehicle.run(5.0)
    assert "Orbit radius limit exceeded" in [m.text for m in pilot.received[since:] if m.get_type() == "STATUSTEXT"]
    assert vehicle.autopilot.mode is FlightMode.ORBIT
    assert math.hypot(vehicle.state.north_m - held.north_m, vehicle.state.east_m - held.east_m) < 0.5
    # DO_SET_MODE cannot ask for Orbit (PX4 reads POSCTL's sub modes as POSCTL); on the ground Orbit changes the
    # mode only.
    assert pilot.command(mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 3, 1) == ACCEPTED
    assert vehicle.autopilot.mode is FlightMode.POSCTL
    assert pilot.command(mavlink.MAV_CMD_NAV_LAND) == ACCEPTED
    pilot.wait_for(lambda: not vehicle.autopilot.armed, 60.0, "landed and disarmed")
    assert pilot.command(ARM, 1) == ACCEPTED
    assert pilot.command(ORBIT, 10.0, 2.0, 0, math.nan, math.nan, math.nan, math.nan) == ACCEPTED
    pilot.vehicle.run(3.0)
    assert vehicle.autopilot.mode is FlightMode.ORBIT and vehicle.state.on_ground


def test_do_change_speed_sets_the_cruising_speed_of_hold_and_rtl_until_the_mode_changes(pilot):
    # MAVSDK's set_current_speed: DO_CHANGE_SPEED, param1 1 (ground speed), param2 the speed. PX4's Navigator takes
    # param2 > 0 as the cruising speed (else resets it), ACCEPTED always, and resets it on a mode change.
    vehicle = airborne(pilot).vehicle
    lat, lon, _ = vehicle.frame.to_geodetic(80.0, 0.0, 0.0)
    assert pilot.command(REPOSITION, -1, 1, 0, math.nan, lat, lon, math.nan) == ACCEPTED
    assert pilot.command(mavlink.MAV_CMD_DO_CHANGE_SPEED, 1, 3.0, -1, 0) == ACCEPTED
    pilot.vehicle.run(8.0)
    assert vehicle.state.vn_mps == pytest.approx(3.0, abs=0.15)
    assert pilot.command(mavlink.MAV_CMD_DO_CHANGE_SPEED, 1, 0.0, -1, 0) == ACCEPTED  # back to MPC_XY_CRUISE
    pilot.vehicle.run(4.0)
    assert vehicle.state.vn_mps == pytest.approx(vehicle.params["MPC_XY_CRUISE"], abs=0.15)
    pilot.wait_for(lambda: vehicle.state.north_m > 78.0 and abs(vehicle.state.vn_mps) < 0.2, 30.0, "the point")
    assert pilot.command(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH) == ACCEPTED
    pilot.wait_for(lambda: -vehicle.state.down_m > vehicle.params["RTL_RETURN_ALT"] - 0.5, 30.0, "the RTL climb")
    assert pilot.command(mavlink.MAV_CMD_DO_CHANGE_SPEED, 1, 2.0, -1, 0) == ACCEPTED
    pilot.vehicle.run(10.0)
    assert vehicle.state.vn_mps == pytest.approx(-2.0, abs=0.15)
    assert pilot.command(mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4, 3) == ACCEPTED
    assert vehicle.autopilot.cruise_speed_mps is None  # a mode change resets it
