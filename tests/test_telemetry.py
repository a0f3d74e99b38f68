"""Telemetry content and rates, as a pymavlink client receives it over the in-memory link."""
from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from missions.geodesy import GeoPoint, LocalFrame
from sitl_bridge import telemetry
from sitl_bridge.px4.modes import FlightMode
from sitl_bridge.scripted_flight import LockstepPilot
from sitl_bridge.vehicle import VehicleConfig
from sitl_bridge.wind import Wind


def received(pilot: LockstepPilot, msg_type: str, since: int = 0) -> list:
    return [m for m in pilot.received[since:] if m.get_type() == msg_type]


def test_default_stream_rates():
    pilot = LockstepPilot.create(VehicleConfig(seed=0))
    pilot.wait_for(lambda: pilot.vehicle.time_s >= 10.0, 11.0, "10 s")
    rates = {name: len(received(pilot, name)) / 10.0 for name in
             ("HEARTBEAT", "SYS_STATUS", "GLOBAL_POSITION_INT", "LOCAL_POSITION_NED", "ATTITUDE",
              "EXTENDED_SYS_STATE", "HOME_POSITION", "BATTERY_STATUS")}
    assert rates["HEARTBEAT"] == pytest.approx(1.0, abs=0.11)
    assert rates["GLOBAL_POSITION_INT"] >= 10.0 and rates["LOCAL_POSITION_NED"] >= 10.0
    assert rates["ATTITUDE"] >= 10.0
    assert rates["HOME_POSITION"] == pytest.approx(0.5, abs=0.11)
    assert rates["SYS_STATUS"] > 0.5 and rates["EXTENDED_SYS_STATE"] > 0.5 and rates["BATTERY_STATUS"] > 0.5


def test_sys_status_health_and_prearm_bits():
    pilot = LockstepPilot.create(VehicleConfig(seed=0))
    status = pilot.wait_message("SYS_STATUS", 2.0)
    for bit in (mavlink.MAV_SYS_STATUS_SENSOR_GPS, mavlink.MAV_SYS_STATUS_PREARM_CHECK,
                mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO, mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL):
        assert status.onboard_control_sensors_present & bit
        assert status.onboard_control_sensors_health & bit
    assert status.battery_remaining == 100 and status.voltage_battery == 16_800
    pilot.vehicle.autopilot.gps_ok = False  # a GPS outage clears both the GPS and the pre-arm health bit
    unhealthy = telemetry.sys_status(pilot.vehicle)
    assert not unhealthy.onboard_control_sensors_health & mavlink.MAV_SYS_STATUS_SENSOR_GPS
    assert not unhealthy.onboard_control_sensors_health & mavlink.MAV_SYS_STATUS_PREARM_CHECK


def test_landed_state_goes_through_takeoff_in_air_landing_on_ground():
    pilot = LockstepPilot.create(VehicleConfig(seed=0, params={"MIS_TAKEOFF_ALT": 5.0}))
    pilot.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    pilot.command(mavlink.MAV_CMD_NAV_TAKEOFF, *[math.nan] * 7)
    pilot.wait_for(lambda: pilot.vehicle.autopilot.mode is FlightMode.HOLD and not pilot.vehicle.state.on_ground,
                   20.0, "takeoff")
    pilot.vehicle.run(2.0)
    pilot.command(mavlink.MAV_CMD_NAV_LAND)
    pilot.wait_for(lambda: not pilot.vehicle.autopilot.armed, 30.0, "landing")
    pilot.vehicle.run(1.0)
    pilot.step()
    states = [m.landed_state for m in received(pilot, "EXTENDED_SYS_STATE")]
    collapsed = [s for i, s in enumerate(states) if i == 0 or s != states[i - 1]]
    assert collapsed == [mavlink.MAV_LANDED_STATE_ON_GROUND, mavlink.MAV_LANDED_STATE_TAKEOFF,
                         mavlink.MAV_LANDED_STATE_IN_AIR, mavlink.MAV_LANDED_STATE_LANDING,
                         mavlink.MAV_LANDED_STATE_ON_GROUND]


def test_global_and_local_positions_agree_through_the_geodetic_conversion():
    home = GeoPoint(-33.8568, 151.2153, 12.0)  # southern and eastern hemispheres
    pilot = LockstepPilot.create(VehicleConfig(home=home, seed=4, params={"MIS_TAKEOFF_ALT": 6.0}))
    pilot.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    pilot.command(mavlink.MAV_CMD_NAV_TAKEOFF, *[math.nan] * 7)
    pilot.wait_for(lambda: pilot.vehicle.time_s > 12.0, 13.0, "climb")
    glob = received(pilot, "GLOBAL_POSITION_INT")[-1]
    local = next(m for m in reversed(pilot.received) if m.get_type() == "LOCAL_POSITION_NED"
                 and m.time_boot_ms == glob.time_boot_ms)
    north, east, down = LocalFrame(home).to_ned(glob.lat * 1e-7, glob.lon * 1e-7, glob.alt * 1e-3)
    assert (north, east, down) == pytest.approx((local.x, local.y, local.z), abs=0.02)  # 1e-7 deg ~ 1 cm
    assert glob.relative_alt * 1e-3 == pytest.approx(-local.z, abs=0.002)
    assert -local.z == pytest.approx(6.0, abs=1.0)
    home_msg = pilot.wait_message("HOME_POSITION", 2.5)
    assert (home_msg.latitude, home_msg.longitude, home_msg.altitude) == (-338568000, 1512153000, 12000)


def test_telemetry_is_noisy_but_close_to_the_truth():
    pilot = LockstepPilot.create(VehicleConfig(seed=9))
    errors = []
    for _ in range(200):
        pilot.vehicle.run(0.1)
        pilot.step()
        local = next(m for m in reversed(pilot.received) if m.get_type() == "LOCAL_POSITION_NED")
        errors.append(math.hypot(local.x - pilot.vehicle.state.north_m, local.y - pilot.vehicle.state.east_m))
    assert max(errors) < 4.0  # GPS noise + wandering bias, not simulator truth
    assert len({round(e, 6) for e in errors}) > 50


def test_battery_drains_in_flight_and_is_reported():
    pilot = LockstepPilot.create(VehicleConfig(seed=0, params={"MIS_TAKEOFF_ALT": 10.0}))
    pilot.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    pilot.command(mavlink.MAV_CMD_NAV_TAKEOFF, *[math.nan] * 7)
    pilot.wait_for(lambda: pilot.vehicle.time_s > 120.0, 121.0, "two minutes of flight")
    battery = received(pilot, "BATTERY_STATUS")[-1]
    assert 80 <= battery.battery_remaining < 100
    assert battery.current_battery > 1000  # more than 10 A while hovering
    assert battery.voltages[0] < 16_800
    assert battery.current_consumed > 0


def test_vehicle_holds_position_in_wind():
    config = VehicleConfig(seed=3, wind=Wind(north_mps=6.0, east_mps=-3.0, gust_mps=1.5, seed=3),
                           params={"MIS_TAKEOFF_ALT": 10.0})
    pilot = LockstepPilot.create(config)
    pilot.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    pilot.command(mavlink.MAV_CMD_NAV_TAKEOFF, *[math.nan] * 7)
    pilot.wait_for(lambda: pilot.vehicle.time_s > 60.0, 61.0, "a minute in the wind")
    state = pilot.vehicle.state
    assert math.hypot(state.north_m, state.east_m) < 3.0 and -state.down_m == pytest.approx(10.0, abs=1.0)
    attitude = received(pilot, "ATTITUDE")[-1]
    # The air moves north: facing north (yaw 0) the vehicle leans back (nose up) to push south against it.
    assert attitude.pitch > 0.01
