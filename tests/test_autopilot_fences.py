"""The autopilots' own geofences (sitl_bridge/px4/geofence.py and sitl_bridge/ardupilot/fence.py), flown in lockstep
with pymavlink: PX4's GF_* cylinder and ArduCopter's FENCE_* circle, ceiling and floor and its uploaded polygons and
circles (FENCE_TYPE bit 4), their actions, texts and pre-arm refusals."""
from __future__ import annotations

import math
import struct

import pytest
from ardupilot_helpers import airborne
from pymavlink.dialects.v20 import common as mavlink

from autonomy.vehicle_link import VehicleLink
from sitl_bridge.ardupilot.fence import fence_names
from sitl_bridge.ardupilot.modes import CopterMode
from sitl_bridge.link import MemoryMavConnection, memory_link_pair
from sitl_bridge.px4.modes import FlightMode
from sitl_bridge.scripted_flight import LockstepPilot
from sitl_bridge.vehicle import SimulatedVehicle, VehicleConfig

ACCEPTED, FAILED = mavlink.MAV_RESULT_ACCEPTED, mavlink.MAV_RESULT_FAILED
TEMPORARILY_REJECTED = mavlink.MAV_RESULT_TEMPORARILY_REJECTED
ARM, TAKEOFF = mavlink.MAV_CMD_COMPONENT_ARM_DISARM, mavlink.MAV_CMD_NAV_TAKEOFF
LOCAL_NED = mavlink.MAV_FRAME_LOCAL_NED
PX4_DISTANCE_TEXT = "Geofence: exceeding maximum distance to Home"
PX4_ALTITUDE_TEXT = "Geofence: exceeding maximum altitude above Home"


def texts(pilot: LockstepPilot, since: int = 0) -> list[str]:
    """The STATUSTEXTs received, chunked ones (a shared non-zero id, numbered by chunk_seq) joined in order."""
    joined: list[str] = []
    chunks: dict[int, dict[int, str]] = {}
    for m in pilot.received[since:]:
        if m.get_type() != "STATUSTEXT":
            continue
        if not m.id and not m.chunk_seq and len(m.text) < 50:  # PX4's first text has id 0 even when chunked
            joined.append(m.text)
        elif len(m.text) < 50:
            parts = {**chunks.pop(m.id, {}), m.chunk_seq: m.text}
            assert sorted(parts) == list(range(len(parts)))
            joined.append("".join(parts[i] for i in sorted(parts)))
        else:
            chunks.setdefault(m.id, {})[m.chunk_seq] = m.text
    return joined


def fly(pilot: LockstepPilot, seconds: float) -> None:
    end = pilot.vehicle.time_s + seconds
    pilot.wait_for(lambda: pilot.vehicle.time_s >= end - 1e-9, seconds + 1, "time")


def distance_from_home(pilot: LockstepPilot) -> float:
    home_n, home_e, _ = pilot.vehicle.autopilot.home_ned
    return math.hypot(pilot.vehicle.state.north_m - home_n, pilot.vehicle.state.east_m - home_e)


def altitude(pilot: LockstepPilot) -> float:
    return pilot.vehicle.autopilot.home_ned[2] - pilot.vehicle.state.down_m


# ---------------------------------------------------------------- PX4
def px4_in_offboard(params: dict, stream=(5.0, 0.0, 0.0, LOCAL_NED)) -> LockstepPilot:
    pilot = LockstepPilot.create(VehicleConfig(seed=4, params={"MIS_TAKEOFF_ALT": 10.0, **params}))
    pilot.wait_for(lambda: pilot.vehicle.autopilot.gps_ok, 2.0, "GPS")
    assert pilot.command(ARM, 1) == ACCEPTED
    assert pilot.command(TAKEOFF, *[math.nan] * 7) == ACCEPTED
    pilot.wait_for(lambda: pilot.vehicle.autopilot.mode is FlightMode.HOLD and not pilot.vehicle.state.on_ground,
                   30.0, "takeoff")
    pilot.stream = stream
    fly(pilot, 1.2)
    assert pilot.set_mode(FlightMode.OFFBOARD) == ACCEPTED
    return pilot


def test_px4_geofence_is_off_by_default():
    pilot = px4_in_offboard({})
    fly(pilot, 30.0)
    assert distance_from_home(pilot) > 120.0 and pilot.vehicle.autopilot.mode is FlightMode.OFFBOARD
    assert not any("Geofence" in t for t in texts(pilot))


def test_px4_horizontal_breach_holds_where_it_was_detected_and_says_why():
    pilot = px4_in_offboard({"GF_MAX_HOR_DIST": 60.0})
    pilot.wait_for(lambda: pilot.heartbeat_mode() is FlightMode.HOLD, 30.0, "geofence hold")
    breach_at = distance_from_home(pilot)
    assert 60.0 <= breach_at < 60.0 + 5.0 * 0.2 + 0.5  # checked every 200 ms, at 5 m/s
    assert texts(pilot).count(PX4_DISTANCE_TEXT) == 1
    fly(pilot, 10.0)  # the stream goes on, but HOLD does not fly it
    assert distance_from_home(pilot) < breach_at + 5.0 and math.hypot(*pilot.vehicle.ground_velocity[:2]) < 0.3


def test_px4_breach_during_a_reposition_stops_there_although_the_vehicle_is_already_in_hold():
    """MAVSDK's goto_location is DO_REPOSITION, which flies in Hold: the fence's Hold action changes no mode then,
    and a simulator that only switched modes would fly on to the target beyond the fence.
    Navigator::geofence_breach_check repositions to the current position on a breach, whatever the mode."""
    pilot = px4_in_offboard({"GF_MAX_HOR_DIST": 60.0}, stream=(0.0, 0.0, 0.0, LOCAL_NED))
    lat, lon, _ = pilot.vehicle.frame.to_geodetic(150.0, 0.0, 0.0)
    pilot.mav.command_int_send(1, 1, mavlink.MAV_FRAME_GLOBAL_INT, mavlink.MAV_CMD_DO_REPOSITION, 0, 0,
                               -1, 1, 0, math.nan, round(lat * 1e7), round(lon * 1e7), math.nan)
    pilot.stream = None
    pilot.wait_for(lambda: PX4_DISTANCE_TEXT in texts(pilot), 60.0, "the breach")
    breach_at = distance_from_home(pilot)
    assert pilot.vehicle.autopilot.mode is FlightMode.HOLD
    fly(pilot, 15.0)
    assert distance_from_home(pilot) < breach_at + 5.0 < 70.0  # stopped at the fence, not 150 m out
    assert math.hypot(*pilot.vehicle.ground_velocity[:2]) < 0.3


def test_px4_hold_is_left_by_a_mode_switch_and_acts_again_only_on_a_new_breach():
    pilot = px4_in_offboard({"GF_MAX_HOR_DIST": 60.0})
    pilot.wait_for(lambda: pilot.heartbeat_mode() is FlightMode.HOLD, 30.0, "geofence hold")
    pilot.stream = (-5.0, 0.0, 0.0, LOCAL_NED)  # back towards home
    assert pilot.set_mode(FlightMode.OFFBOARD) == ACCEPTED  # the user escapes (AlwaysModeSwitchOnly)
    pilot.wait_for(lambda: distance_from_home(pilot) < 40.0, 30.0, "inside again")
    assert pilot.vehicle.autopilot.mode is FlightMode.OFFBOARD
    pilot.stream = (5.0, 0.0, 0.0, LOCAL_NED)
    pilot.wait_for(lambda: pilot.heartbeat_mode() is FlightMode.HOLD, 30.0, "second breach")
    assert texts(pilot).count(PX4_DISTANCE_TEXT) == 2


@pytest.mark.parametrize("action, mode", [(3, FlightMode.RTL), (5, FlightMode.LAND)])
def test_px4_vertical_breach_takes_gf_action(action, mode):
    pilot = px4_in_offboard({"GF_MAX_VER_DIST": 20.0, "GF_ACTION": action}, stream=(0.0, 0.0, -2.0, LOCAL_NED))
    pilot.wait_for(lambda: pilot.heartbeat_mode() is mode, 30.0, "geofence action")
    assert 20.0 <= altitude(pilot) < 21.0 and PX4_ALTITUDE_TEXT in texts(pilot)


def test_px4_warning_action_only_warns_and_none_does_nothing():
    warned = px4_in_offboard({"GF_MAX_HOR_DIST": 60.0, "GF_ACTION": 1})
    fly(warned, 20.0)
    assert distance_from_home(warned) > 90.0 and warned.vehicle.autopilot.mode is FlightMode.OFFBOARD
    assert texts(warned).count(PX4_DISTANCE_TEXT) == 1
    ignored = px4_in_offboard({"GF_MAX_HOR_DIST": 60.0, "GF_ACTION": 0})
    fly(ignored, 20.0)
    assert ignored.vehicle.autopilot.mode is FlightMode.OFFBOARD and PX4_DISTANCE_TEXT not in texts(ignored)


def test_actions_not_emulated_are_refused_and_the_old_value_echoed():
    px4 = LockstepPilot.create(VehicleConfig(seed=4))
    echoed = px4.set_param("GF_ACTION", 4)  # Terminate
    assert struct.unpack("<i", struct.pack("<f", echoed)) == (2,) and px4.vehicle.params["GF_ACTION"] == 2
    copter = LockstepPilot.create(VehicleConfig(autopilot="ardupilot", seed=5))
    assert copter.set_param("FENCE_ACTION", 3) == 1  # SmartRTL is not emulated


# ---------------------------------------------------------------- ArduCopter
def copter_in_guided(params: dict) -> LockstepPilot:
    return airborne(params, seed=5)


FENCE = {"FENCE_ENABLE": 1, "FENCE_RADIUS": 60.0}


def test_fence_names_as_ardupilot_lists_them():
    assert fence_names(2) == "Circle fence"
    assert fence_names(1 | 2) == "Max Alt and Circle fences"
    assert fence_names(1 | 2 | 8) == "Max Alt, Circle and Min Alt fences"


def test_copter_fence_is_off_by_default():
    pilot = copter_in_guided({})
    pilot.stream = (5.0, 0.0, 0.0, LOCAL_NED)
    fly(pilot, 80.0)
    assert distance_from_home(pilot) > 350.0 and pilot.vehicle.autopilot.mode is CopterMode.GUIDED


def test_copter_circle_breach_returns_home_and_clears():
    pilot = copter_in_guided(FENCE)
    pilot.stream = (5.0, 0.0, 0.0, LOCAL_NED)
    pilot.wait_for(lambda: pilot.heartbeat_mode() is CopterMode.RTL, 30.0, "fence RTL")
    breached_s = pilot.vehicle.time_s
    assert 60.0 <= distance_from_home(pilot) < 60.0 + 5.0 * 0.04 + 0.2  # 25 Hz checks
    assert "Circle fence breached" in texts(pilot)
    pilot.stream = None
    pilot.wait_for(lambda: distance_from_home(pilot) < 55.0, 60.0, "back inside")
    # the switch to RTL started a manual recovery, in which breaches are still tracked (and cleared)
    assert "Manual recovery started" in texts(pilot)
    pilot.wait_for(lambda: "Fence breach cleared" in texts(pilot), 1.0, "cleared")
    assert pilot.vehicle.time_s - breached_s < 10.0
    pilot.wait_for(lambda: not pilot.vehicle.autopilot.armed, 120.0, "RTL lands and disarms")


def test_copter_ceiling_breach_with_always_land():
    pilot = copter_in_guided({**FENCE, "FENCE_ALT_MAX": 20.0, "FENCE_ACTION": 2})
    pilot.stream = (0.0, 0.0, -2.0, LOCAL_NED)
    pilot.wait_for(lambda: pilot.heartbeat_mode() is CopterMode.LAND, 30.0, "fence LAND")
    assert "Max Alt fence breached" in texts(pilot) and altitude(pilot) >= 20.0


def test_copter_floor_arms_above_it_and_catches_a_descent_towards_the_water():
    pilot = copter_in_guided({**FENCE, "FENCE_TYPE": 15, "FENCE_ALT_MIN": 5.0})
    assert "Min Alt fence enabled (auto enable)" in texts(pilot)  # at 5 + FENCE_MARGIN m on the climb
    pilot.stream = (0.0, 0.0, 1.0, LOCAL_NED)  # down
    pilot.wait_for(lambda: pilot.heartbeat_mode() is CopterMode.RTL, 30.0, "floor RTL")
    assert "Min Alt fence breached" in texts(pilot) and 4.5 < altitude(pilot) <= 5.0


def test_copter_mode_change_during_a_breach_starts_ten_seconds_of_manual_recovery():
    pilot = copter_in_guided(FENCE)
    pilot.stream = (5.0, 0.0, 0.0, LOCAL_NED)
    pilot.wait_for(lambda: pilot.heartbeat_mode() is CopterMode.RTL, 30.0, "fence RTL")
    breach_at = distance_from_home(pilot)
    assert pilot.set_mode(CopterMode.GUIDED) == ACCEPTED  # the operator takes it back and flies on outwards
    start = pilot.vehicle.time_s
    pilot.wait_for(lambda: pilot.heartbeat_mode() is CopterMode.RTL, 30.0, "backup fence")
    # ignored for 10 s; then the breach is old, and only the backup fence 20 m beyond it is a new one
    assert pilot.vehicle.time_s - start >= 10.0 and distance_from_home(pilot) >= breach_at + 20.0
    assert texts(pilot).count("Circle fence breached") == 2


def test_copter_breach_beyond_100_m_lands_instead_of_returning():
    pilot = copter_in_guided({**FENCE, "FENCE_ACTION": 0})  # report only while it flies far out
    pilot.stream = (10.0, 0.0, 0.0, LOCAL_NED)
    pilot.wait_for(lambda: distance_from_home(pilot) > 180.0, 60.0, "far out")
    assert pilot.vehicle.autopilot.mode is CopterMode.GUIDED and "Circle fence breached" in texts(pilot)
    assert pilot.set_param("FENCE_ACTION", 1) == 1
    pilot.wait_for(lambda: pilot.heartbeat_mode() is CopterMode.LAND, 10.0, "backup breach, give-up distance")


def test_copter_fence_prearm_checks():
    pilot = LockstepPilot.create(VehicleConfig(autopilot="ardupilot", seed=5,
                                               params={**FENCE, "FENCE_TYPE": 4}))
    pilot.wait_for(lambda: pilot.vehicle.autopilot.gps_ok, 2.0, "GPS")
    assert pilot.set_mode(CopterMode.GUIDED) == ACCEPTED
    assert pilot.command(ARM, 1) == FAILED
    assert "PreArm: Fences enabled, but none selected" in texts(pilot)
    pilot.set_param("FENCE_TYPE", 7)
    pilot.set_param("FENCE_ALT_MAX", 10.0)
    pilot.set_param("FENCE_ALT_MIN", 8.0)
    assert pilot.command(ARM, 1) == FAILED
    assert "PreArm: FENCE_MARGIN too big" in texts(pilot)
    pilot.set_param("FENCE_ALT_MIN", -10.0)
    assert pilot.command(ARM, 1) == ACCEPTED


def copter_with_uploaded_fence(params: dict, fence: list | None = None) -> LockstepPilot:
    """An ArduCopter on the ground with its GPS fix and ``fence(pilot)`` uploaded (by default a 40 m inclusion
    square)."""
    from px4_mission_helpers import square_fence, upload

    pilot = LockstepPilot.create(VehicleConfig(autopilot="ardupilot", seed=5, params=params))
    pilot.wait_for(lambda: pilot.vehicle.autopilot.gps_ok, 2.0, "GPS")
    fence = square_fence(pilot, half_m=40.0) if fence is None else fence(pilot)
    assert upload(pilot, fence, mission_type=mavlink.MAV_MISSION_TYPE_FENCE)[0] == mavlink.MAV_MISSION_ACCEPTED
    return pilot


def take_off(pilot: LockstepPilot) -> None:
    assert pilot.set_mode(CopterMode.GUIDED) == ACCEPTED and pilot.command(ARM, 1) == ACCEPTED
    assert pilot.command(TAKEOFF, 0, 0, 0, 0, 0, 0, 10.0) == ACCEPTED
    pilot.wait_for(lambda: not pilot.vehicle.autopilot.taking_off and not pilot.vehicle.state.on_ground, 30,
                   "takeoff")


def test_copter_polygon_fence_breach_returns_home():
    pilot = copter_with_uploaded_fence({"FENCE_ENABLE": 1})  # FENCE_TYPE 7 has the polygon bit
    take_off(pilot)
    pilot.stream = (0.0, 5.0, 0.0, LOCAL_NED)
    pilot.wait_for(lambda: pilot.heartbeat_mode() is CopterMode.RTL, 30.0, "fence RTL")
    assert 40.0 <= pilot.vehicle.state.east_m < 40.0 + 5.0 * 0.04 + 0.2  # caught at the square's edge (25 Hz)
    assert "Polygon fence breached" in texts(pilot)
    pilot.stream = None
    pilot.wait_for(lambda: not pilot.vehicle.autopilot.armed, 120.0, "RTL lands and disarms")
    assert distance_from_home(pilot) < 1.5 and "Fence breach cleared" in texts(pilot)


def test_copter_uploaded_fence_needs_the_polygon_bit():
    pilot = copter_with_uploaded_fence({"FENCE_ENABLE": 1, "FENCE_TYPE": 3})  # max altitude and circle only
    take_off(pilot)
    pilot.stream = (0.0, 5.0, 0.0, LOCAL_NED)
    pilot.wait_for(lambda: pilot.vehicle.state.east_m > 60.0, 30.0, "past the square")
    assert pilot.vehicle.autopilot.mode is CopterMode.GUIDED and "Polygon fence breached" not in texts(pilot)


def test_copter_uploaded_fence_prearm_checks():
    from px4_mission_helpers import fence_item

    def circle(command: int, north: float, radius_m: float):
        return lambda pilot: [fence_item(pilot, 0, command, north, 0.0, radius_m)]

    pilot = copter_with_uploaded_fence({"FENCE_ENABLE": 1}, circle(mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, 5, 20))
    fly(pilot, 0.1)  # the fence is checked at 25 Hz, armed or not
    assert pilot.set_mode(CopterMode.GUIDED) == ACCEPTED and pilot.command(ARM, 1) == FAILED
    assert "PreArm: Vehicle breaching Polygon fence" in texts(pilot)  # home is in the exclusion circle
    pilot = copter_with_uploaded_fence({"FENCE_ENABLE": 1}, circle(mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, 0, 1.5))
    assert pilot.set_mode(CopterMode.GUIDED) == ACCEPTED and pilot.command(ARM, 1) == FAILED
    assert "PreArm: Polygon fence margin is greater than inclusion circle radius" in texts(pilot)  # FENCE_MARGIN 2
    pilot = copter_with_uploaded_fence({"FENCE_ENABLE": 1, "FENCE_TYPE": 4})  # polygons only: present with a fence
    assert pilot.set_mode(CopterMode.GUIDED) == ACCEPTED and pilot.command(ARM, 1) == ACCEPTED


# ---------------------------------------------------------------- long texts
LONG = "x" * 50 + "y" * 50  # fills two chunks exactly
CHUNKS = {  # (id, chunk_seq, text) on the wire for "short", LONG, the geofence text
    "px4": [(0, 0, "short"), (1, 0, LONG[:50]), (1, 1, LONG[50:]), (2, 0, PX4_DISTANCE_TEXT)],  # STATUSTEXT.hpp
    "ardupilot": [(0, 0, "short"), (1, 0, LONG[:50]), (1, 1, LONG[50:]), (1, 2, ""),  # GCS::send_textv
                  (0, 0, PX4_DISTANCE_TEXT)]}


@pytest.mark.parametrize("autopilot", ["px4", "ardupilot"])
def test_long_texts_go_in_chunks_as_each_autopilot_sends_them_and_the_runners_link_joins_them(autopilot):
    """PX4 numbers every text and sends nothing after a full last chunk; ArduPilot numbers long texts only and
    closes a full one with an empty chunk. The runner's link gets the same three texts from both."""
    vehicle_end, client_end = memory_link_pair()
    vehicle = SimulatedVehicle(VehicleConfig(autopilot=autopilot, seed=4), [vehicle_end])
    link = VehicleLink(MemoryMavConnection(client_end, source_system=1, source_component=191), lambda: vehicle.time_s)
    for _ in range(100):  # a second: the vehicle boots and the link hears it
        vehicle.step()
        link.tick()
    received = []
    for text in ("short", LONG, PX4_DISTANCE_TEXT):
        vehicle.autopilot._event(vehicle.time_s, text, mavlink.MAV_SEVERITY_CRITICAL)
        vehicle.step()
        received += [m for m in link.tick() if m.get_type() == "STATUSTEXT"]
    assert [(m.id, m.chunk_seq, m.text) for m in received] == CHUNKS[autopilot]
    assert link.status_texts[-3:] == ["short", LONG, PX4_DISTANCE_TEXT]


def test_px4s_first_text_has_id_0_and_its_chunks_are_still_joined():
    """PX4's ids count from 0 on each link (STATUSTEXT.hpp ``msg.id = _id++``), so a long first text goes out in
    chunks of id 0, which MAVLink reserves for single-message texts: the runner's link joins them from PX4."""
    vehicle_end, client_end = memory_link_pair()
    vehicle = SimulatedVehicle(VehicleConfig(seed=4), [vehicle_end])
    link = VehicleLink(MemoryMavConnection(client_end, source_system=1, source_component=191), lambda: vehicle.time_s)
    for _ in range(100):
        vehicle.step()
        link.tick()
    received = []
    for text in (LONG, "short"):
        vehicle.autopilot._event(vehicle.time_s, text, mavlink.MAV_SEVERITY_CRITICAL)
        vehicle.step()
        received += [m for m in link.tick() if m.get_type() == "STATUSTEXT"]
    assert [(m.id, m.chunk_seq) for m in received] == [(0, 0), (0, 1), (1, 0)]
    assert link.status_texts[-2:] == [LONG, "short"]
