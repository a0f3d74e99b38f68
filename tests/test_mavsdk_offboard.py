"""MAVSDK (the ``mavsdk`` package's asyncio API) flies PX4's offboard examples against the simulated vehicle over
real UDP.

``mavsdk`` 4.x is the native binding: the gRPC package's ``System()`` (``drone.connect``, ``drone.offboard``) is gone
(constructing it raises TypeError with a migration hint). MAVSDK's documented offboard examples (MAVSDK-Python
examples/offboard_velocity_ned.py, offboard_position_ned.py, offboard_position_velocity_ned.py) are therefore flown
here with the 4.x API: the same sequence of calls (connect, wait for global position and home, arm, one initial
setpoint, start offboard at once, the legs, stop offboard), then land; and takeoff, NED and body velocities, RTL and
land, and a global position setpoint.

MAVSDK listens with ``udpin://0.0.0.0:PORT`` and the vehicle's API link sends to PORT, as with PX4 SITL. Every await
is bounded; the vehicle runs at 2x real time to keep the test short (mavsdk_helpers.py).
"""
from __future__ import annotations

import asyncio
import math

import pytest

mavsdk = pytest.importorskip("mavsdk.asyncio")
from mavsdk.asyncio.plugins.action import ActionAsync  # noqa: E402
from mavsdk.asyncio.plugins.offboard import (  # noqa: E402
    OffboardAsync, PositionGlobalYaw, PositionNedYaw, VelocityBodyYawspeed, VelocityNedYaw)
from mavsdk.asyncio.plugins.telemetry import FlightMode, LandedState, TelemetryAsync  # noqa: E402
from mavsdk_helpers import AT_THE_POINT_M, SPEED, T, autopilot_at, bounded, first, sim_sleep, vehicle_server  # noqa: E402

from sitl_bridge.server import UdpPorts, VehicleServer  # noqa: E402
from sitl_bridge.vehicle import VehicleConfig  # noqa: E402

pytestmark = [pytest.mark.slow, pytest.mark.mavsdk]


async def fly(port: int, server: VehicleServer) -> None:
    vehicle = server.vehicle
    async with autopilot_at(port) as system:
        action, telemetry, offboard = ActionAsync(system), TelemetryAsync(system), OffboardAsync(system)

        await first(telemetry.subscribe_health(),
                    lambda h: h.is_global_position_ok and h.is_home_position_ok and h.is_armable, 20, "health")
        await bounded(action.set_takeoff_altitude(8.0))
        assert vehicle.params["MIS_TAKEOFF_ALT"] == 8.0
        await bounded(action.arm())
        await first(telemetry.subscribe_armed(), bool, T, "armed")
        await bounded(action.takeoff())
        await first(telemetry.subscribe_position(), lambda p: p.relative_altitude_m > 7.0, 20, "8 m")
        await first(telemetry.subscribe_flight_mode(), lambda m: m == FlightMode.HOLD, T, "HOLD after takeoff")
        assert -vehicle.state.down_m == pytest.approx(8.0, abs=1.0)

        # Offboard: one setpoint (MAVSDK then streams it at 20 Hz) and the switch at once, as PX4 accepts it.
        await bounded(offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, 0.0, 0.0)))
        await bounded(offboard.start())
        await first(telemetry.subscribe_flight_mode(), lambda m: m == FlightMode.OFFBOARD, T, "OFFBOARD")

        # NED: 3 m/s north for 4 s, facing east (yaw 90 deg).
        start = vehicle.state
        await bounded(offboard.set_velocity_ned(VelocityNedYaw(3.0, 0.0, 0.0, 90.0)))
        await sim_sleep(4.0)
        moved_n, moved_e = vehicle.state.north_m - start.north_m, vehicle.state.east_m - start.east_m
        assert 9.0 < moved_n < 13.0 and abs(moved_e) < 1.0
        assert math.degrees(vehicle.state.yaw_rad) == pytest.approx(90.0, abs=3.0)

        # Body frame: after a stop, "forward" is east; 2 m/s for 3 s.
        await bounded(offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, 0.0, 90.0)))
        await sim_sleep(2.0)
        start = vehicle.state
        await bounded(offboard.set_velocity_body(VelocityBodyYawspeed(2.0, 0.0, 0.0, 0.0)))
        await sim_sleep(3.0)
        moved_n, moved_e = vehicle.state.north_m - start.north_m, vehicle.state.east_m - start.east_m
        assert 4.5 < moved_e < 6.5 and abs(moved_n) < 0.5
        pv = await bounded(telemetry.position_velocity_ned())
        assert pv.velocity.east_m_s == pytest.approx(2.0, abs=0.5)

        await bounded(offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, 0.0, 90.0)))
        await bounded(offboard.stop())
        await first(telemetry.subscribe_flight_mode(), lambda m: m != FlightMode.OFFBOARD, T, "leaving OFFBOARD")

        await bounded(action.return_to_launch())
        await first(telemetry.subscribe_flight_mode(), lambda m: m == FlightMode.RETURN_TO_LAUNCH, T, "RTL")
        await first(telemetry.subscribe_landed_state(), lambda s: s == LandedState.ON_GROUND, 60, "landed")
        await first(telemetry.subscribe_armed(), lambda armed: not armed, 20, "disarmed")
        assert math.hypot(vehicle.state.north_m, vehicle.state.east_m) < 1.0  # back home


async def fly_offboard_example(port: int, server: VehicleServer) -> dict[str, tuple[float, ...]]:
    """MAVSDK's offboard_velocity_ned.py, step for step (sleeps in simulated seconds); returns each leg's
    ground velocity (north, east, down, m/s), heading (deg) and altitude (m) at its end, by leg name."""
    vehicle = server.vehicle
    legs = {}
    async with autopilot_at(port) as system:
        action, telemetry, offboard = ActionAsync(system), TelemetryAsync(system), OffboardAsync(system)
        await first(telemetry.subscribe_health(), lambda h: h.is_global_position_ok and h.is_home_position_ok,
                    20, "global position estimate")
        await bounded(action.arm())  # "-- Arming"
        await bounded(offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, 0.0, 0.0)))  # "-- Setting initial setpoint"
        await bounded(offboard.start())  # "-- Starting offboard": no wait before it
        await first(telemetry.subscribe_flight_mode(), lambda m: m == FlightMode.OFFBOARD, T, "OFFBOARD")
        for name, setpoint, seconds in (("up", VelocityNedYaw(0.0, 0.0, -2.0, 0.0), 4.0),
                                        ("north", VelocityNedYaw(2.0, 0.0, 0.0, 90.0), 4.0),
                                        ("south", VelocityNedYaw(-2.0, 0.0, 0.0, 270.0), 4.0),
                                        ("west", VelocityNedYaw(0.0, -2.0, 0.0, 90.0), 4.0),
                                        ("east", VelocityNedYaw(0.0, 2.0, 0.0, 90.0), 4.0),
                                        ("turn south", VelocityNedYaw(0.0, 0.0, 0.0, 180.0), 2.0),
                                        ("down", VelocityNedYaw(0.0, 0.0, 1.0, 0.0), 4.0)):
            await bounded(offboard.set_velocity_ned(setpoint))
            await sim_sleep(seconds)
            vn, ve, vd = vehicle.ground_velocity
            legs[name] = (vn, ve, vd, math.degrees(vehicle.state.yaw_rad) % 360.0, -vehicle.state.down_m)
        await bounded(offboard.stop())  # "-- Stopping offboard"
        await first(telemetry.subscribe_flight_mode(), lambda m: m != FlightMode.OFFBOARD, T, "leaving OFFBOARD")
        await bounded(action.land())
        await first(telemetry.subscribe_landed_state(), lambda s: s == LandedState.ON_GROUND, 60, "landed")
        await first(telemetry.subscribe_armed(), lambda armed: not armed, 20, "disarmed")
    return legs


def test_mavsdk_offboard_velocity_ned_example_flies_as_documented(udp_ports):
    api_port, mavsdk_port = udp_ports[:2]
    config = VehicleConfig(seed=6, boot_time_s=600.0)  # an autopilot that booted ten minutes earlier
    with VehicleServer(config, UdpPorts(api_port=api_port, api_remote_port=mavsdk_port, gcs_remote_port=None),
                       speed=SPEED) as server:
        legs = asyncio.run(asyncio.wait_for(fly_offboard_example(mavsdk_port, server), 150))
        assert server.error is None and server.vehicle.handler_errors == 0
    expected = {"up": (0, 0, -2, 0), "north": (2, 0, 0, 90), "south": (-2, 0, 0, 270), "west": (0, -2, 0, 90),
                "east": (0, 2, 0, 90), "turn south": (0, 0, 0, 180), "down": (0, 0, 1, 0)}
    for name, (vn, ve, vd, heading) in expected.items():
        flown = legs[name]
        assert flown[:3] == pytest.approx((vn, ve, vd), abs=0.3), name
        assert abs((flown[3] - heading + 180.0) % 360.0 - 180.0) < 5.0, name
    assert legs["up"][4] == pytest.approx(7.0, abs=1.5)  # took off in OFFBOARD: 2 m/s for 4 s, less the spin-up
    assert server.vehicle.state.on_ground and not server.vehicle.autopilot.armed


def test_mavsdk_flies_takeoff_offboard_ned_and_body_rtl_and_land(udp_ports):
    api_port, mavsdk_port = udp_ports[:2]
    config = VehicleConfig(seed=5, params={"RTL_RETURN_ALT": 10.0})
    with VehicleServer(config, UdpPorts(api_port=api_port, api_remote_port=mavsdk_port, gcs_remote_port=None),
                       speed=SPEED) as server:
        asyncio.run(asyncio.wait_for(fly(mavsdk_port, server), 150))
        assert server.error is None
        assert server.vehicle.handler_errors == 0


async def fly_position_examples(port: int, server: VehicleServer, with_velocity: bool) -> list[tuple[float, ...]]:
    """MAVSDK-Python's offboard_position_ned.py (arm at once, position legs, stop offboard) or, ``with_velocity``,
    offboard_position_velocity_ned.py (wait for health, arm, position + velocity legs, land, stop offboard), step
    for step with sleeps in simulated seconds. Returns (north, east, down, heading deg) at the end of each leg."""
    vehicle = server.vehicle
    legs = []
    async with autopilot_at(port) as system:
        action, telemetry, offboard = ActionAsync(system), TelemetryAsync(system), OffboardAsync(system)
        if with_velocity:
            await first(telemetry.subscribe_health(), lambda h: h.is_global_position_ok and h.is_home_position_ok,
                        20, "global position estimate")
        await bounded(action.arm())
        await bounded(offboard.set_position_ned(PositionNedYaw(0.0, 0.0, 0.0, 0.0)))  # "-- Setting initial setpoint"
        await bounded(offboard.start())
        if with_velocity:
            steps = [((0.0, 0.0, -10.0, 0.0), (0.0, 0.0, -1.0, 0.0), 10.0),
                     ((50.0, 0.0, -10.0, 0.0), (1.0, 0.0, 0.0, 0.0), 20.0)]
        else:
            steps = [((0.0, 0.0, -5.0, 0.0), None, 10.0), ((5.0, 0.0, -5.0, 90.0), None, 10.0),
                     ((5.0, 10.0, -5.0, 90.0), None, 15.0), ((0.0, 10.0, 0.0, 180.0), None, 10.0)]
        for position, velocity, seconds in steps:
            if velocity is None:
                await bounded(offboard.set_position_ned(PositionNedYaw(*position)))
            else:
                await bounded(offboard.set_position_velocity_ned(PositionNedYaw(*position), VelocityNedYaw(*velocity)))
            await sim_sleep(seconds)
            state = vehicle.state
            legs.append((state.north_m, state.east_m, state.down_m, math.degrees(state.yaw_rad) % 360.0))
        if with_velocity:
            await bounded(action.land())
        await bounded(offboard.stop())  # MAVSDK's stop switches to Hold, even from LAND
        return legs


def flown_position_example(udp_ports: list[int], seed: int, with_velocity: bool) -> tuple[list, str]:
    """:func:`fly_position_examples` against a PX4 vehicle: the legs and the mode the example left it in. Every
    setpoint MAVSDK streamed was taken."""
    server, mavsdk_port = vehicle_server(udp_ports, seed)
    with server:
        legs = asyncio.run(asyncio.wait_for(fly_position_examples(mavsdk_port, server, with_velocity), 120))
        assert server.error is None and server.vehicle.handler_errors == 0
        assert not server.vehicle.autopilot.setpoints_ignored
        return legs, server.vehicle.autopilot.status.mode_name


def test_mavsdk_offboard_position_ned_example_flies_as_documented(udp_ports):
    legs, _ = flown_position_example(udp_ports, 10, with_velocity=False)
    expected = [(0.0, 0.0, -5.0, 0.0), (5.0, 0.0, -5.0, 90.0), (5.0, 10.0, -5.0, 90.0), (0.0, 10.0, 0.0, 180.0)]
    for flown, (north, east, down, heading) in zip(legs, expected):
        assert flown[:3] == pytest.approx((north, east, down), abs=0.3)
        assert abs((flown[3] - heading + 180.0) % 360.0 - 180.0) < 2.0


def test_mavsdk_offboard_position_velocity_ned_example_flies_the_positions_with_feedforward(udp_ports):
    # set_position_velocity_ned sends both groups; PX4 flies the position with the velocity as feed-forward, so
    # each leg settles about v_ff / MPC_XY_P (about 1 m) beyond its point along the feed-forward.
    legs, mode = flown_position_example(udp_ports, 11, with_velocity=True)
    (n1, e1, d1, _), (n2, e2, d2, _) = legs
    assert abs(n1) < 0.3 and abs(e1) < 0.3 and -11.6 < d1 < -10.3  # up 10 m, about 1 m over it
    assert 50.3 < n2 < 51.6 and abs(e2) < 0.3 and d2 == pytest.approx(-10.0, abs=0.3)
    assert mode == "HOLD"  # land, then offboard.stop(): the example ends hovering in Hold


async def fly_global_offboard(port: int, server: VehicleServer, target: tuple[float, float]) -> str:
    """Offboard with MAVSDK's set_position_global (SET_POSITION_TARGET_GLOBAL_INT, altitude above home): take off,
    one setpoint 12 m above home facing east, start offboard, wait at the point; returns the mode then."""
    async with autopilot_at(port) as system:
        action, telemetry, offboard = ActionAsync(system), TelemetryAsync(system), OffboardAsync(system)
        await first(telemetry.subscribe_health(), lambda h: h.is_global_position_ok and h.is_home_position_ok,
                    20, "global position estimate")
        await bounded(action.arm())
        await bounded(action.takeoff())
        await first(telemetry.subscribe_position(), lambda p: p.relative_altitude_m > 2.0, 20, "airborne")
        await bounded(offboard.set_position_global(
            PositionGlobalYaw(target[0], target[1], 12.0, 90.0, PositionGlobalYaw.AltitudeType.REL_HOME)))
        await bounded(offboard.start())
        await first(telemetry.subscribe_position(),
                    lambda p: abs(p.latitude_deg - target[0]) < 1e-5 and abs(p.longitude_deg - target[1]) < 1e-5
                    and abs(p.relative_altitude_m - 12.0) < 0.5, 60, "the global setpoint")
        return server.vehicle.autopilot.status.mode_name


def test_mavsdk_offboard_global_position_flies_to_the_point(udp_ports):
    server, mavsdk_port = vehicle_server(udp_ports, 14)
    with server:
        target = server.vehicle.frame.to_geodetic(40.0, 25.0, 0.0)[:2]
        mode = asyncio.run(asyncio.wait_for(fly_global_offboard(mavsdk_port, server, target), 90))
        assert server.error is None and server.vehicle.handler_errors == 0
        state = server.vehicle.state
        assert not server.vehicle.autopilot.setpoints_ignored
    assert mode == "OFFBOARD" and math.hypot(state.north_m - 40.0, state.east_m - 25.0) < AT_THE_POINT_M
    assert math.degrees(state.yaw_rad) == pytest.approx(90.0, abs=3.0)
