"""Realism options of the simulated vehicle: boot time, reboots, telemetry profiles, home, and their validation.

All lockstep over the in-memory link, read by pymavlink: what a companion computer would see.
"""
from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from missions.geodesy import GeoPoint
from sitl_bridge.ardupilot.modes import CopterMode
from sitl_bridge.link import MemoryMavConnection, memory_link_pair
from sitl_bridge.px4.modes import FlightMode
from sitl_bridge.scripted_flight import LockstepPilot
from sitl_bridge.vehicle import SimulatedVehicle, VehicleConfig

ARM, TAKEOFF = mavlink.MAV_CMD_COMPONENT_ARM_DISARM, mavlink.MAV_CMD_NAV_TAKEOFF


def fly(pilot: LockstepPilot, seconds: float) -> None:
    end = pilot.vehicle.time_s + seconds
    pilot.wait_for(lambda: pilot.vehicle.time_s >= end - 1e-9, seconds + 1, "time")


def received(pilot: LockstepPilot, msg_type: str, since: int = 0) -> list:
    return [m for m in pilot.received[since:] if m.get_type() == msg_type]


# ---------------------------------------------------------------- boot time
@pytest.mark.parametrize("autopilot", ["px4", "ardupilot"])
def test_boot_time_puts_every_boot_relative_time_minutes_ahead(autopilot):
    pilot = LockstepPilot.create(VehicleConfig(autopilot=autopilot, boot_time_s=600.0, seed=2,
                                               telemetry_profile="legacy"))
    fly(pilot, 2.0)
    position = received(pilot, "GLOBAL_POSITION_INT")[-1]
    assert position.time_boot_ms == pytest.approx(602_000, abs=110)
    assert received(pilot, "GPS_RAW_INT")[-1].time_usec == pytest.approx(602e6, abs=1.1e6)
    pilot.mav.timesync_send(0, 77)
    assert pilot.wait_message("TIMESYNC", 0.5).tc1 == pytest.approx(602e9, rel=1e-3)
    assert pilot.vehicle.time_s == pytest.approx(2.0, abs=0.02)  # the simulation itself still starts at 0


# ---------------------------------------------------------------- reboots
def test_a_px4_reboot_in_the_air_goes_silent_drops_the_vehicle_and_comes_back_fresh():
    config = VehicleConfig(seed=4, boot_time_s=300.0, reboot_at_s=20.0, reboot_downtime_s=5.0,
                           params={"MIS_TAKEOFF_ALT": 15.0})
    pilot = LockstepPilot.create(config)
    pilot.command(ARM, 1)
    pilot.command(TAKEOFF, *[math.nan] * 7)
    pilot.wait_for(lambda: pilot.vehicle.time_s >= 19.9, 21, "before the reboot")
    assert -pilot.vehicle.state.down_m == pytest.approx(15.0, abs=0.5) and pilot.vehicle.autopilot.armed
    before = received(pilot, "LOCAL_POSITION_NED")[-1].time_boot_ms
    assert before == pytest.approx(319_900, abs=110)
    pilot.wait_for(lambda: not pilot.vehicle.powered, 0.2, "the reboot")
    seen = len(pilot.received)
    pilot.wait_for(lambda: pilot.vehicle.time_s >= 24.9, 6, "downtime")
    assert pilot.received[seen:] == []  # silent while it boots
    assert pilot.vehicle.state.on_ground  # motors stopped: it fell
    pilot.wait_message("HEARTBEAT", 1.5)
    after = pilot.received[seen:]
    assert after[0].get_seq() == 0  # a new MAVLink instance: sequence numbers restart
    beat = received(pilot, "HEARTBEAT", seen)[0]
    assert FlightMode.from_custom_mode(beat.custom_mode) is FlightMode.HOLD
    assert not beat.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED and not pilot.vehicle.autopilot.armed
    fly(pilot, 2.0)
    local = received(pilot, "LOCAL_POSITION_NED", seen)
    assert local[0].time_boot_ms < 6_000  # time since the new boot, not since the first
    assert math.hypot(local[-1].x, local[-1].y) < 3.0  # the origin was re-set where the vehicle now lies
    home = pilot.wait_message("HOME_POSITION", 2.5)
    assert home.altitude == pytest.approx(config.home.alt_m * 1000, abs=50)  # on the ground where it fell
    assert pilot.vehicle.reboots == 1


def test_an_ardupilot_reboot_comes_back_in_stabilize_disarmed_with_its_parameters():
    config = VehicleConfig(autopilot="ardupilot", seed=4, reboot_at_s=5.0, reboot_downtime_s=2.0)
    pilot = LockstepPilot.create(config)
    pilot.wait_message("HEARTBEAT", 2.0)
    pilot.set_mode(CopterMode.LOITER)
    assert pilot.set_param("GUID_TIMEOUT", 1.5) == pytest.approx(1.5)
    pilot.wait_for(lambda: pilot.vehicle.time_s >= 7.5, 8, "reboot")
    beat = received(pilot, "HEARTBEAT")[-1]
    assert beat.custom_mode == CopterMode.STABILIZE  # INITIAL_MODE
    assert pilot.vehicle.params["GUID_TIMEOUT"] == 1.5  # stored parameters survive a reboot
    assert pilot.vehicle.time_boot_ms == pytest.approx(2_500, abs=10)


def test_reboot_options_are_validated():
    with pytest.raises(ValueError, match=r"VehicleConfig.reboot_downtime_s must be a number in \[0.1, 600\]"):
        VehicleConfig(reboot_at_s=3.0, reboot_downtime_s=0.0)
    with pytest.raises(ValueError, match=r"VehicleConfig.reboot_at_s must be a number in \[0, 1e\+07\]"):
        VehicleConfig(reboot_at_s=-1.0)
    with pytest.raises(ValueError, match=r"VehicleConfig.boot_time_s must be a number in \[0, 1e\+07\]"):
        VehicleConfig(boot_time_s=math.nan)
    with pytest.raises(ValueError, match="VehicleConfig.autopilot must be one of px4, ardupilot, got 'apm'"):
        VehicleConfig(autopilot="apm")
    with pytest.raises(ValueError, match="VehicleConfig.telemetry_profile must be one of default, legacy"):
        VehicleConfig(telemetry_profile="fast")
    with pytest.raises(ValueError, match="unknown parameter 'COM_OF_LOSS_T'"):
        SimulatedVehicle(VehicleConfig(autopilot="ardupilot", params={"COM_OF_LOSS_T": 2.0}))


# ---------------------------------------------------------------- telemetry profiles
def two_link_vehicle(profile: str) -> tuple[SimulatedVehicle, dict[str, MemoryMavConnection]]:
    ends = {name: memory_link_pair(name) for name in ("api", "gcs")}
    vehicle = SimulatedVehicle(VehicleConfig(seed=1, telemetry_profile=profile), [ends["api"][0], ends["gcs"][0]])
    return vehicle, {name: MemoryMavConnection(pair[1]) for name, pair in ends.items()}


def rates_per_link(profile: str, seconds: float = 4.0) -> dict[str, dict[str, float]]:
    vehicle, clients = two_link_vehicle(profile)
    counts: dict[str, dict[str, int]] = {name: {} for name in clients}
    vehicle.run(1.0)  # past the first GPS fix
    for conn in clients.values():
        while conn.recv_msg() is not None:
            pass
    for _ in range(int(seconds / vehicle.dt_s)):
        vehicle.step()
        for name, conn in clients.items():
            while (msg := conn.recv_msg()) is not None:
                counts[name][msg.get_type()] = counts[name].get(msg.get_type(), 0) + 1
    return {name: {t: n / seconds for t, n in c.items()} for name, c in counts.items()}


def test_px4_profile_streams_onboard_rates_on_the_api_link_and_normal_rates_on_the_gcs_link():
    rates = rates_per_link("px4")
    api, gcs = rates["api"], rates["gcs"]
    assert api["GLOBAL_POSITION_INT"] == pytest.approx(50, abs=1)
    assert gcs["GLOBAL_POSITION_INT"] == pytest.approx(5, abs=0.5)
    assert api["LOCAL_POSITION_NED"] == pytest.approx(30, abs=1)
    assert gcs["LOCAL_POSITION_NED"] == pytest.approx(1, abs=0.3)
    assert api["ATTITUDE"] == pytest.approx(100, abs=1) and gcs["ATTITUDE"] == pytest.approx(15, abs=1)
    assert api["HEARTBEAT"] == pytest.approx(1, abs=0.3) and gcs["BATTERY_STATUS"] == pytest.approx(0.5, abs=0.3)


def test_px4_sitl_profile_raises_the_gcs_link_like_px4_rc_mavlink_and_legacy_stays_the_same_everywhere():
    sitl = rates_per_link("px4_sitl")["gcs"]
    assert sitl["LOCAL_POSITION_NED"] == pytest.approx(50, abs=1) and sitl["ATTITUDE"] == pytest.approx(50, abs=1)
    legacy = rates_per_link("legacy")
    assert legacy["api"]["GLOBAL_POSITION_INT"] == legacy["gcs"]["GLOBAL_POSITION_INT"] == pytest.approx(10, abs=0.5)


# ---------------------------------------------------------------- home
@pytest.mark.parametrize("autopilot", ["px4", "ardupilot"])
def test_a_home_at_sea_level_is_what_home_position_and_global_position_say(autopilot):
    home = GeoPoint(43.0, 5.3, 0.0)
    pilot = LockstepPilot.create(VehicleConfig(autopilot=autopilot, home=home, seed=3, telemetry_profile="legacy"))
    pilot.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HOME_POSITION)
    fly(pilot, 2.0)
    message = received(pilot, "HOME_POSITION")[-1]
    assert (message.latitude, message.longitude, message.altitude) == (430_000_000, 53_000_000, 0)
    assert received(pilot, "GLOBAL_POSITION_INT")[-1].alt == pytest.approx(0, abs=2_000)
