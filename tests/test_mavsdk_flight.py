"""MAVSDK (the ``mavsdk`` package's asyncio API) flies the simulated vehicle over real UDP.

MAVSDK listens with ``udpin://0.0.0.0:PORT`` and the vehicle's API link sends to PORT, as with PX4 SITL.
Every await is bounded; the vehicle runs at 2x real time to keep the test short.

``mavsdk`` 4.x is the native binding: the gRPC package's ``System()`` (``drone.connect``, ``drone.offboard``) is
gone (constructing it raises TypeError with a migration hint). MAVSDK's documented offboard example
(MAVSDK-Python examples/offboard_velocity_ned.py) is therefore flown here with the 4.x API: the same sequence of
calls (connect, wait for global position and home, arm, one initial setpoint, start offboard at once, velocity
legs, stop offboard), then land. Against the ArduPilot personality: takeoff, goto and land once the companion link
streams (ArduPilot's documented SRx_ fix), and what MAVSDK knows without (docs/sitl.md, "MAVSDK and ArduPilot").
"""
from __future__ import annotations

import asyncio
import contextlib
import math

import pytest

mavsdk = pytest.importorskip("mavsdk.asyncio")
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.asyncio.plugins.action import ActionAsync, OrbitYawBehavior  # noqa: E402
from mavsdk.asyncio.plugins.offboard import (  # noqa: E402
    OffboardAsync, PositionGlobalYaw, PositionNedYaw, VelocityBodyYawspeed, VelocityNedYaw)
from mavsdk.asyncio.plugins.telemetry import FlightMode, LandedState, TelemetryAsync  # noqa: E402

from sitl_bridge.server import UdpPorts, VehicleServer  # noqa: E402
from sitl_bridge.vehicle import VehicleConfig  # noqa: E402

pytestmark = [pytest.mark.slow, pytest.mark.mavsdk]
SPEED = 2.0  # simulated seconds per wall second
T = 10.0  # default bound on one await, wall seconds
AT_THE_POINT_M = 2.5
"""How far the vehicle's true position may be from a point it was sent to once MAVSDK reports it there (within
1e-5 degrees): the autopilot steers on its GPS fix, whose error is a wandering bias of 0.5 m std per axis plus 0.3 m
of noise (sitl_bridge/sensors.py), about 0.8 m radial std; 1.5 m failed once in a fresh clone (1.69 m)."""


async def first(stream, predicate, timeout_s: float, what: str):
    """The first item of an async stream that satisfies ``predicate``; the stream is always closed."""
    async def scan():
        async for item in stream:
            if predicate(item):
                return item

    async with contextlib.aclosing(stream):
        try:
            return await asyncio.wait_for(scan(), timeout_s)
        except asyncio.TimeoutError:
            raise AssertionError(f"MAVSDK: timed out after {timeout_s} s waiting for {what}") from None


_inflight: set[asyncio.Future] = set()


async def bounded(call, timeout_s: float = T):
    """Await a MAVSDK call with a bound, keeping its executor task tracked: MAVSDK runs each call in a
    thread that a timeout cannot stop, and destroying MAVSDK under a blocked call would hang the test."""
    task = asyncio.ensure_future(call)
    _inflight.add(task)
    task.add_done_callback(_inflight.discard)
    return await asyncio.wait_for(asyncio.shield(task), timeout_s)


async def sim_sleep(seconds: float) -> None:
    await asyncio.sleep(seconds / SPEED)


@contextlib.asynccontextmanager
async def autopilot_at(port: int):
    """MAVSDK listening on ``port`` until it sees the autopilot ("Waiting for drone to connect..."); yields that
    system. MAVSDK is destroyed afterwards, never under a blocked call (it times its own calls out within 3 s)."""
    drone = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        await bounded(drone.add_any_connection(f"udpin://0.0.0.0:{port}"))
        system = await bounded(drone.first_autopilot(timeout_s=T), T + 2)
        assert system is not None, "MAVSDK saw no autopilot"
        yield system
    finally:
        if _inflight:
            await asyncio.wait(set(_inflight), timeout=5)
        drone.destroy()


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



def vehicle_server(udp_ports: list[int], seed: int, autopilot: str = "px4",
                   params: dict[str, float] | None = None) -> tuple[VehicleServer, int]:
    """A vehicle whose API link talks to MAVSDK on the second port (not started); returns it and that port."""
    api_port, mavsdk_port = udp_ports[:2]
    config = VehicleConfig(seed=seed, autopilot=autopilot, params=params or {})
    ports = UdpPorts(api_port=api_port, api_remote_port=mavsdk_port, gcs_remote_port=None)
    return VehicleServer(config, ports, speed=SPEED), mavsdk_port


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

# --- MAVSDK and the ArduPilot personality -------------------------------------------------------------------------
# ArduCopter streams nothing until asked (SRn_* = 0) and MAVSDK asks ArduPilot for no stream: its health flags come
# from SYS_STATUS alone (MAVSDK telemetry_impl.cpp, process_sys_status). ArduPilot's documented fix for a companion
# computer is to set the link's SRx_ parameters (ardupilot.org/dev/docs/mavlink-requesting-data.html); docs/sitl.md.
COMPANION_STREAMS = {"SR0_EXT_STAT": 2.0, "SR0_POSITION": 5.0, "SR0_EXTRA1": 4.0}  # the API link is link 0 here


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


def test_the_runners_mavsdk_link_hears_the_autopilots_status_texts(udp_ports):
    """The runner's safety vetoes read the autopilot's STATUSTEXTs (autonomy.link_loss): the MAVSDK backend gets them
    from Telemetry.status_text, joined as the pymavlink backend joins them."""
    import time

    from autonomy.mavsdk_link import MavsdkLink

    server, mavsdk_port = vehicle_server(udp_ports, 11)
    with server:
        link = MavsdkLink(f"udpin:0.0.0.0:{mavsdk_port}", time.monotonic)
        try:
            text = "Geofence: exceeding maximum distance to Home"  # PX4's health check text (sitl_bridge.px4.geofence)
            deadline = time.monotonic() + T
            while text not in [t for _, t in link.status_since(0)] and time.monotonic() < deadline:
                server.vehicle.autopilot._event(server.vehicle.time_s, text, 2)  # again until MAVSDK has subscribed
                time.sleep(0.5)
            received = [t for _, t in link.status_since(0)]
        finally:
            link.close()
    assert text in received and link.status_count == len(received)
    assert link.status_since(link.status_count) == []


def test_the_runners_mavsdk_link_probes_the_uplink_with_timesync(udp_ports):
    """The uplink probe (autonomy.uplink_probe) through MAVSDK's MavlinkDirect plugin: requests with tc1 = 0 go out,
    the vehicle's replies come back with the same ts1, and the probe counts them answered."""
    import time

    from autonomy.mavsdk_link import MavsdkLink
    from autonomy.uplink_probe import UplinkProbe, UplinkProbeConfig

    server, mavsdk_port = vehicle_server(udp_ports, 12)
    with server:
        link = MavsdkLink(f"udpin:0.0.0.0:{mavsdk_port}", time.monotonic)
        try:
            probe = UplinkProbe(UplinkProbeConfig(), link.send_timesync_request)
            deadline = time.monotonic() + T
            while probe.answered < 5 and time.monotonic() < deadline:
                probe.tick(time.monotonic(), link.take_timesync_replies(), active=True)
                time.sleep(0.1)
            link.send_timesync_request(424242)
            while 424242 not in (replies := link.take_timesync_replies()) and time.monotonic() < deadline:
                time.sleep(0.05)
        finally:
            link.close()
    assert probe.answered >= 5 and probe.sent - probe.answered <= 2  # the last ones may still be in flight
    assert 424242 in replies
