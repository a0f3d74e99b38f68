"""The ArduPilot Copter personality, flown by pymavlink over the in-memory link in lockstep.

Each test states what ArduCopter does (its source is cited in docs/sitl.md) and checks the simulated vehicle
does the same: heartbeat fields, mode numbers, arming and its texts, takeoff, GUIDED and GUID_TIMEOUT, RTL and
LAND, auto-disarm, the GCS and battery failsafes, float parameters, stream requests and HOME_POSITION.
"""
from __future__ import annotations

import math

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.ardupilot.modes import CopterMode
from sitl_bridge.scripted_flight import LockstepPilot
from sitl_bridge.vehicle import VehicleConfig

ACCEPTED, FAILED, DENIED = mavlink.MAV_RESULT_ACCEPTED, mavlink.MAV_RESULT_FAILED, mavlink.MAV_RESULT_DENIED
ARM, TAKEOFF = mavlink.MAV_CMD_COMPONENT_ARM_DISARM, mavlink.MAV_CMD_NAV_TAKEOFF
LOCAL_NED, BODY_NED = mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_NED
VELOCITY, POSITION = 3527, 3576


def copter(params: dict | None = None, seed: int = 3, **config) -> LockstepPilot:
    pilot = LockstepPilot.create(VehicleConfig(autopilot="ardupilot", seed=seed, params=params or {}, **config))
    pilot.wait_message("HEARTBEAT", 2.0)
    return pilot


def texts(pilot: LockstepPilot, since: int = 0) -> list[str]:
    return [m.text for m in pilot.received[since:] if m.get_type() == "STATUSTEXT"]


def last(pilot: LockstepPilot, msg_type: str):
    return next(m for m in reversed(pilot.received) if m.get_type() == msg_type)


def fly(pilot: LockstepPilot, seconds: float) -> None:
    end = pilot.vehicle.time_s + seconds
    pilot.wait_for(lambda: pilot.vehicle.time_s >= end - 1e-9, seconds + 1, "time")


def airborne(params: dict | None = None, alt_m: float = 10.0, **config) -> LockstepPilot:
    pilot = copter(params, **config)
    assert pilot.set_mode(CopterMode.GUIDED) == ACCEPTED
    assert pilot.command(ARM, 1) == ACCEPTED
    assert pilot.command(TAKEOFF, 0, 0, 0, 0, 0, 0, alt_m) == ACCEPTED
    pilot.wait_for(lambda: not pilot.vehicle.autopilot.taking_off and not pilot.vehicle.state.on_ground, 30,
                   "takeoff")
    return pilot


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


# ---------------------------------------------------------------- parameters, capabilities, streams, home
def test_parameters_are_floats_with_ardupilot_types():
    pilot = copter()
    pilot.mav.param_request_read_send(1, 1, b"FS_GCS_ENABLE", -1)
    fs = pilot.wait_message("PARAM_VALUE", 0.5)
    assert (fs.param_type, fs.param_value) == (mavlink.MAV_PARAM_TYPE_INT8, 0.0)  # a float, not bytewise
    pilot.mav.param_set_send(1, 1, b"RTL_ALT", 2499.995, mavlink.MAV_PARAM_TYPE_INT32)
    echo = pilot.wait_message("PARAM_VALUE", 0.5)
    assert (echo.param_id, echo.param_value) == ("RTL_ALT", 2500.0)  # AP_Param::set_float: +0.01, truncated
    assert pilot.set_param("GUID_TIMEOUT", 1.5) == pytest.approx(1.5)
    before = len(pilot.received)
    assert pilot.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION) == ACCEPTED
    version = next(m for m in pilot.received[before:] if m.get_type() == "AUTOPILOT_VERSION")
    assert version.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    assert version.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
    assert not version.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
    assert version.flight_sw_version >> 24 == 4
    # GCS_Common.cpp handle_command_request_message: an id with no ap_message is FAILED (PX4 says DENIED)
    assert pilot.command(mavlink.MAV_CMD_REQUEST_MESSAGE, 65000) == mavlink.MAV_RESULT_FAILED


def rate(pilot: LockstepPilot, msg_type: str, seconds: float) -> float:
    seen = len(pilot.received)
    fly(pilot, seconds)
    return sum(1 for m in pilot.received[seen:] if m.get_type() == msg_type) / seconds


def test_nothing_streams_until_requested_then_data_streams_and_intervals():
    pilot = copter()
    assert rate(pilot, "GLOBAL_POSITION_INT", 3.0) == 0.0 and rate(pilot, "HEARTBEAT", 4.0) == pytest.approx(1.0)
    pilot.mav.request_data_stream_send(1, 1, mavlink.MAV_DATA_STREAM_POSITION, 5, 1)
    assert rate(pilot, "GLOBAL_POSITION_INT", 4.0) == pytest.approx(5.0, abs=0.3)
    assert rate(pilot, "ATTITUDE", 2.0) == 0.0  # another group
    assert pilot.vehicle.params["SR0_POSITION"] == 5
    pilot.mav.request_data_stream_send(1, 1, mavlink.MAV_DATA_STREAM_ALL, 2, 1)
    assert rate(pilot, "ATTITUDE", 4.0) == pytest.approx(2.0, abs=0.3)
    pilot.mav.request_data_stream_send(1, 1, mavlink.MAV_DATA_STREAM_ALL, 0, 0)
    assert rate(pilot, "LOCAL_POSITION_NED", 2.0) == 0.0
    assert pilot.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
                         500_000) == ACCEPTED
    assert rate(pilot, "EXTENDED_SYS_STATE", 4.0) == pytest.approx(2.0, abs=0.3)


def test_sr_parameters_at_boot_set_the_link_rates():
    pilot = copter({"SR0_POSITION": 4, "SR0_EXTRA1": 10})
    assert rate(pilot, "LOCAL_POSITION_NED", 3.0) == pytest.approx(4.0, abs=0.4)
    assert rate(pilot, "ATTITUDE", 2.0) == pytest.approx(10.0, abs=0.6)


def test_home_position_when_set_at_arming_and_on_request_never_streamed():
    pilot = copter()
    assert sum(m.get_type() == "HOME_POSITION" for m in pilot.received) == 1  # sent when home is first set
    fly(pilot, 5.0)
    assert sum(m.get_type() == "HOME_POSITION" for m in pilot.received) == 1
    seen = len(pilot.received)
    assert pilot.command(mavlink.MAV_CMD_GET_HOME_POSITION) == ACCEPTED
    home = next(m for m in pilot.received[seen:] if m.get_type() == "HOME_POSITION")
    assert (home.latitude, home.altitude) == (round(pilot.vehicle.config.home.lat_deg * 1e7), 488_000)
    seen = len(pilot.received)
    pilot.set_mode(CopterMode.GUIDED)
    pilot.command(ARM, 1)
    assert any(m.get_type() == "HOME_POSITION" for m in pilot.received[seen:])  # re-set where it arms


def test_no_home_yet_means_an_accepted_request_and_nothing_sent(monkeypatch):
    """GCS_Common.cpp: REQUEST_MESSAGE HOME_POSITION is ACCEPTED and send_home_position() returns before home is set
    (GET_HOME_POSITION says FAILED then)."""
    pilot = copter()
    suite = type(pilot.vehicle.sensors)
    update = suite.update
    monkeypatch.setattr(suite, "update", lambda self, *args: (update(self, *args), setattr(self, "gps", None)))
    fly(pilot, 0.1)  # a receiver without a fix
    seen = len(pilot.received)
    assert pilot.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HOME_POSITION) == ACCEPTED
    assert pilot.command(mavlink.MAV_CMD_GET_HOME_POSITION) == FAILED
    assert not [m for m in pilot.received[seen:] if m.get_type() == "HOME_POSITION"]


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
