"""MAVSDK (the ``mavsdk`` package's asyncio API) flies the simulated vehicle with its Action plugin over real UDP:
MAVSDK-Python's goto.py and do_orbit.py examples against PX4, and against the ArduPilot personality takeoff, goto
and land once the companion link streams (ArduPilot's documented SRx_ fix), and what MAVSDK knows without
(docs/sitl.md, "MAVSDK and ArduPilot").

MAVSDK listens with ``udpin://0.0.0.0:PORT`` and the vehicle's API link sends to PORT, as with PX4 SITL. Every await
is bounded; the vehicle runs at 2x real time to keep the test short (mavsdk_helpers.py).
"""
from __future__ import annotations

import asyncio
import math

import pytest

mavsdk = pytest.importorskip("mavsdk.asyncio")
from mavsdk.asyncio.plugins.action import ActionAsync, OrbitYawBehavior  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import FlightMode, TelemetryAsync  # noqa: E402
from mavsdk_helpers import (  # noqa: E402
    AT_THE_POINT_M, COMPANION_STREAMS, SPEED, T, autopilot_at, bounded, first, sim_sleep, vehicle_server)

from sitl_bridge.server import UdpPorts, VehicleServer  # noqa: E402
from sitl_bridge.vehicle import VehicleConfig  # noqa: E402

pytestmark = [pytest.mark.slow, pytest.mark.mavsdk]


async def fly_goto_example(port: int, server: VehicleServer, target: tuple[float, float]) -> float:
    """MAVSDK-Python's examples/goto.py with the 4.x API: wait for a global position, read home's AMSL altitude,
    arm, take off, wait a second, goto_location 20 m above home. Returns the AMSL altitude it asked for."""
    async with autopilot_at(port) as system:
        action, telemetry = ActionAsync(system), TelemetryAsync(system)
        await first(telemetry.subscribe_health(), lambda h: h.is_global_position_ok, 20, "global position")
        home = await first(telemetry.subscribe_home(), lambda h: True, T, "home")
        await bounded(action.arm())
        await bounded(action.takeoff())
        await sim_sleep(1.0)
        flying_alt = home.absolute_altitude_m + 20.0  # "to fly drone 20 m above the ground plane"
        await bounded(action.goto_location(target[0], target[1], flying_alt, 0.0))
        await first(telemetry.subscribe_position(),
                    lambda p: abs(p.latitude_deg - target[0]) < 1e-5 and abs(p.longitude_deg - target[1]) < 1e-5
                    and abs(p.absolute_altitude_m - flying_alt) < 1.0, 60, "the goto point")
        await first(telemetry.subscribe_flight_mode(), lambda m: m == FlightMode.HOLD, T, "HOLD there")
        return flying_alt


def test_mavsdk_goto_example_flies_to_the_point_and_holds(udp_ports):
    # MAVSDK's goto_location is PX4's DO_REPOSITION (docs/sitl.md): the example's flow, to a point about 120 m
    # from home (the example's own is 800 m away, 160 s of flight).
    api_port, mavsdk_port = udp_ports[:2]
    config = VehicleConfig(seed=7)
    with VehicleServer(config, UdpPorts(api_port=api_port, api_remote_port=mavsdk_port, gcs_remote_port=None),
                       speed=SPEED) as server:
        target = server.vehicle.frame.to_geodetic(70.0, -100.0, 0.0)[:2]
        flying_alt = asyncio.run(asyncio.wait_for(fly_goto_example(mavsdk_port, server, target), 120))
        assert server.error is None and server.vehicle.handler_errors == 0
        state = server.vehicle.state
        assert math.hypot(state.north_m - 70.0, state.east_m + 100.0) < AT_THE_POINT_M
        assert config.home.alt_m - state.down_m == pytest.approx(flying_alt, abs=1.0)
        assert server.vehicle.autopilot.armed and not state.on_ground


ORBIT_CENTRE = (47.398036222362471, 8.5450146439425509)  # do_orbit.py's, about 55 m from PX4 SITL's home


async def fly_orbit_example(port: int, server: VehicleServer) -> tuple[list[tuple[float, ...]], float]:
    """MAVSDK-Python's do_orbit.py with sleeps in simulated seconds: wait for health, read the position, arm, take
    off, wait 10 s, orbit its centre at 10 m radius and 2 m/s facing the centre, 10 m above the start, for 60 s,
    then return to launch. Returns (distance from the centre, ground speed, altitude AMSL, heading error to the
    centre in degrees) once a second over the orbit's last 20 s, and the altitude it asked for."""
    vehicle = server.vehicle
    centre = vehicle.frame.to_ned(*ORBIT_CENTRE, 0.0)[:2]
    samples = []
    async with autopilot_at(port) as system:
        action, telemetry = ActionAsync(system), TelemetryAsync(system)
        await first(telemetry.subscribe_health(), lambda h: h.is_global_position_ok and h.is_home_position_ok,
                    20, "global position estimate")
        position = await first(telemetry.subscribe_position(), lambda p: True, T, "a position")
        orbit_height = position.absolute_altitude_m + 10
        await bounded(action.arm())
        await bounded(action.takeoff())
        await sim_sleep(10.0)
        await bounded(action.do_orbit(10, 2, OrbitYawBehavior.HOLD_FRONT_TO_CIRCLE_CENTER, *ORBIT_CENTRE,
                                      orbit_height))
        await sim_sleep(40.0)
        for _ in range(20):
            await sim_sleep(1.0)
            s = vehicle.state
            dn, de = s.north_m - centre[0], s.east_m - centre[1]
            error = math.degrees(math.remainder(math.atan2(-de, -dn) - s.yaw_rad, math.tau))
            samples.append((math.hypot(dn, de), math.hypot(s.vn_mps, s.ve_mps),
                            vehicle.config.home.alt_m - s.down_m, error))
        await bounded(action.return_to_launch())
        await first(telemetry.subscribe_flight_mode(), lambda m: m == FlightMode.RETURN_TO_LAUNCH, T, "RTL")
        return samples, orbit_height


def test_mavsdk_do_orbit_example_circles_its_centre_facing_it(udp_ports):
    # MAVSDK's do_orbit is PX4's Orbit mode (MAV_CMD_DO_ORBIT, sitl_bridge/px4/orbit.py, docs/sitl.md).
    server, mavsdk_port = vehicle_server(udp_ports, 13)
    with server:
        samples, orbit_height = asyncio.run(asyncio.wait_for(fly_orbit_example(mavsdk_port, server), 120))
        assert server.error is None and server.vehicle.handler_errors == 0
    for distance, speed, altitude, heading_error in samples:
        assert distance == pytest.approx(10.0, abs=0.5) and speed == pytest.approx(2.0, abs=0.2)
        assert altitude == pytest.approx(orbit_height, abs=1.0) and abs(heading_error) < 5.0


# --- MAVSDK and the ArduPilot personality -------------------------------------------------------------------------
# ArduCopter streams nothing until asked (SRn_* = 0) and MAVSDK asks ArduPilot for no stream: its health flags come
# from SYS_STATUS alone (MAVSDK telemetry_impl.cpp, process_sys_status). ArduPilot's documented fix for a companion
# computer is to set the link's SRx_ parameters (ardupilot.org/dev/docs/mavlink-requesting-data.html); docs/sitl.md.
# COMPANION_STREAMS (mavsdk_helpers.py) sets them on the API link.
async def fly_ardupilot_takeoff_goto_land(port: int, server: VehicleServer, north_m: float) -> list[str]:
    """MAVSDK-Python's takeoff_and_land.py (wait for a global position and home, arm, take off, land) with
    ArduPilot's own example's takeoff altitude (ArduPilot/ardupilot-mavsdk examples/actions/actions.cpp:
    set_takeoff_altitude(10)) and a goto_location ``north_m`` north at the same altitude between takeoff and
    landing. Returns the vehicle's mode after each step."""
    vehicle = server.vehicle
    modes = []
    async with autopilot_at(port) as system:
        action, telemetry = ActionAsync(system), TelemetryAsync(system)
        await first(telemetry.subscribe_health(), lambda h: h.is_global_position_ok and h.is_home_position_ok, 20,
                    "a global position and home")
        await bounded(action.arm())
        modes.append(vehicle.autopilot.status.mode_name)
        await bounded(action.set_takeoff_altitude(10.0))
        await bounded(action.takeoff())  # MAVSDK switches ArduPilot to GUIDED, then NAV_TAKEOFF with param7 10 m
        modes.append(vehicle.autopilot.status.mode_name)
        here = await first(telemetry.subscribe_position(), lambda p: p.relative_altitude_m > 9.5, 30, "10 m up")
        target = vehicle.frame.to_geodetic(vehicle.state.north_m + north_m, vehicle.state.east_m, 0.0)[:2]
        await bounded(action.goto_location(target[0], target[1], here.absolute_altitude_m, 0.0))
        modes.append(vehicle.autopilot.status.mode_name)
        await first(telemetry.subscribe_position(),
                    lambda p: abs(p.latitude_deg - target[0]) < 1e-5 and abs(p.longitude_deg - target[1]) < 1e-5,
                    60, "the goto point")
        await bounded(action.land())
        modes.append(vehicle.autopilot.status.mode_name)
        await first(telemetry.subscribe_in_air(), lambda in_air: not in_air, 60, "on the ground")
        await first(telemetry.subscribe_armed(), lambda armed: not armed, 30, "disarmed by the autopilot")
        return modes


def test_mavsdk_flies_ardupilot_take_off_goto_and_land_once_the_companion_link_streams(udp_ports):
    server, mavsdk_port = vehicle_server(udp_ports, 8, "ardupilot", COMPANION_STREAMS)
    with server:
        start = server.vehicle.state
        modes = asyncio.run(asyncio.wait_for(fly_ardupilot_takeoff_goto_land(mavsdk_port, server, 60.0), 180))
        assert server.error is None and server.vehicle.handler_errors == 0
        state = server.vehicle.state
    assert modes == ["STABILIZE", "GUIDED", "GUIDED", "LAND"]  # armed in STABILIZE, ArduCopter's INITIAL_MODE 0
    assert math.hypot(state.north_m - start.north_m - 60.0, state.east_m - start.east_m) < AT_THE_POINT_M  # landed
    assert state.on_ground and not server.vehicle.autopilot.armed


async def health_when_home_arrives(port: int, server: VehicleServer):
    """MAVSDK's health at the moment home is known, then ArduPilot's own example's first step (arm without
    waiting for health: ardupilot-mavsdk examples/actions/actions.cpp comments that wait out)."""
    async with autopilot_at(port) as system:
        action, telemetry = ActionAsync(system), TelemetryAsync(system)
        health = await first(telemetry.subscribe_health(), lambda h: h.is_home_position_ok, 20, "home")
        await bounded(action.arm())
        return health


def test_mavsdk_on_a_default_ardupilot_knows_home_but_no_health_and_can_still_arm(udp_ports):
    # Home comes from MAVSDK's own HOME_POSITION request; nothing sends SYS_STATUS, so every health flag read from
    # it stays at MAVSDK's default, False, although the vehicle is armable (the arm succeeds).
    server, mavsdk_port = vehicle_server(udp_ports, 9, "ardupilot")
    with server:
        health = asyncio.run(asyncio.wait_for(health_when_home_arrives(mavsdk_port, server), 60))
        assert server.error is None and server.vehicle.handler_errors == 0
        armed = server.vehicle.autopilot.armed
    assert health.is_home_position_ok
    assert not (health.is_global_position_ok or health.is_local_position_ok or health.is_armable
                or health.is_gyrometer_calibration_ok)
    assert armed
