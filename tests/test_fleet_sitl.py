"""Several simulated vehicles in one process (``hrlsac sitl --count N``), numbered as PX4's and ArduPilot's SITL
instances are: system ids, ports, homes along an offset line; all of them on one ground-station port, where pymavlink,
MAVSDK and MAVProxy see every vehicle and fly one while the others stay on the ground."""
from __future__ import annotations

import asyncio
import contextlib
import math
import signal
import subprocess
import sys
import time

import pytest
from conftest import UdpClient, free_udp_ports
from pymavlink.dialects.v20 import common as mavlink

from missions.geodesy import LocalFrame
from sitl_bridge.cli import main as sitl_main
from sitl_bridge.px4.modes import FlightMode
from sitl_bridge.server import UdpPorts, VehicleServer, fleet_configs
from sitl_bridge.vehicle_config import DEFAULT_HOME, VehicleConfig

SPEED = 2.0


def test_instance_ports_follow_px4_and_ardupilot_sitl():
    assert UdpPorts.for_instance("px4", 0) == UdpPorts()  # PX4 SITL's single instance
    second = UdpPorts.for_instance("px4", 1)
    assert (second.api_port, second.api_remote_port, second.gcs_port, second.gcs_remote_port) == (14581, 14541,
                                                                                                  18571, 14550)
    assert UdpPorts.for_instance("px4", 10).api_remote_port == 14549  # px4-rc.mavlink: the same port from 10 on
    third = UdpPorts.for_instance("ardupilot", 2)
    assert (third.tcp_port, third.gcs_port, third.gcs_remote_port, third.api_port, third.api_remote_port) == (
        5780, 14580, 14550, 14581, 14571)


def test_fleet_configs_number_the_vehicles_and_space_their_homes_along_the_line():
    configs = fleet_configs(VehicleConfig(seed=5), 3, first_instance=1, offset_line=(90.0, 40.0))
    assert [c.system_id for c in configs] == [2, 3, 4] and [c.seed for c in configs] == [5, 6, 7]
    frame = LocalFrame(DEFAULT_HOME)
    offsets = [frame.to_ned(c.home.lat_deg, c.home.lon_deg, c.home.alt_m) for c in configs]
    assert [round(e, 3) for _, e, _ in offsets] == [0.0, 40.0, 80.0] and all(abs(n) < 1e-6 for n, _, _ in offsets)
    px4 = fleet_configs(VehicleConfig(), 2)  # PX4's default: sitl_multiple_run.sh, 3 m north apart
    assert frame.to_ned(px4[1].home.lat_deg, px4[1].home.lon_deg, px4[1].home.alt_m)[0] == pytest.approx(3.0)


@pytest.mark.parametrize("argv, message", [
    (["--count", "0"], "--count must be in [1, 32], got 0"),
    (["--count", "2", "--pty"], "--pty serves one vehicle"),
    (["--count", "2", "--param", "MAV_SYS_ID=5"], "--param MAV_SYS_ID: with --count each instance N is system N+1"),
    (["--count", "2", "--offset-line", "90"], "--offset-line: expected 2 comma-separated numbers"),
])
def test_bad_fleet_options_are_refused_in_one_line(capsys, argv, message):
    assert sitl_main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def heartbeat_of(client: UdpClient, system: int):
    return next((m for m in reversed(client.received) if m.get_type() == "HEARTBEAT"
                 and m.get_srcSystem() == system), None)


def position_of(client: UdpClient, system: int):
    return next((m for m in reversed(client.received) if m.get_type() == "GLOBAL_POSITION_INT"
                 and m.get_srcSystem() == system), None)


def armed(heartbeat) -> bool:
    return heartbeat is not None and bool(heartbeat.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)


@pytest.mark.slow
def test_hrlsac_sitl_count_3_shows_three_systems_on_one_gcs_port_and_pymavlink_flies_vehicle_2(tmp_path):
    api_port, api_remote, gcs_port, gcs_remote = free_udp_ports(4)
    # the base ports move up by one per instance: leave room for three
    api_port, api_remote, gcs_port = api_port + 100, api_remote + 200, gcs_port + 300
    sitl = subprocess.Popen([sys.executable, "-m", "hrlsac_cli", "sitl", "--count", "3", "--speed", str(SPEED),
                             "--offset-line", "90,40", "--api-port", str(api_port), "--api-remote", str(api_remote),
                             "--gcs-port", str(gcs_port), "--gcs-remote", str(gcs_remote)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    gcs = UdpClient(f"udpin:127.0.0.1:{gcs_remote}")
    second = None
    try:
        gcs.wait(lambda: all(position_of(gcs, system) for system in (1, 2, 3)), 10.0, "three vehicles' positions")
        positions = {system: position_of(gcs, system) for system in (1, 2, 3)}
        frame = LocalFrame(DEFAULT_HOME)
        east = [frame.to_ned(p.lat / 1e7, p.lon / 1e7, p.alt / 1e3)[1] for p in positions.values()]
        assert east == pytest.approx([0.0, 40.0, 80.0], abs=3.0)  # distinct positions, 40 m apart

        # pymavlink flies vehicle 2 on its own API port: arm, take off, OFFBOARD, east at 3 m/s
        second = UdpClient(f"udpin:127.0.0.1:{api_remote + 1}")
        second.target_system = 2
        second.wait(lambda: position_of(second, 2), 5.0, "vehicle 2's position")
        assert {m.get_srcSystem() for m in second.received} == {2}
        assert second.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == mavlink.MAV_RESULT_ACCEPTED
        home_alt = position_of(second, 2).alt / 1e3 - position_of(second, 2).relative_alt / 1e3
        takeoff = second.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, home_alt + 10)
        assert takeoff.result == mavlink.MAV_RESULT_ACCEPTED
        second.wait(lambda: position_of(second, 2).relative_alt > 9_000, 20.0, "vehicle 2 at 10 m")
        second.stream = (0.0, 3.0, 0.0)
        second.pump(1.0)
        assert second.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 6, 0).result == mavlink.MAV_RESULT_ACCEPTED
        for _ in range(30):  # vehicle 2's stream goes on while the ground station listens
            second.pump(0.1)
            gcs.pump(0.02)
        assert FlightMode.from_custom_mode(heartbeat_of(gcs, 2).custom_mode) is FlightMode.OFFBOARD
        assert armed(heartbeat_of(gcs, 2)) and position_of(gcs, 2).relative_alt > 9_000
        assert position_of(gcs, 2).vy > 200  # cm/s east
        for system in (1, 3):  # untouched, on the ground
            assert not armed(heartbeat_of(gcs, system)) and abs(position_of(gcs, system).relative_alt) < 500
    finally:
        for client in (gcs, second):
            if client is not None:
                client.close()
        sitl.send_signal(signal.SIGINT)
        out, _ = sitl.communicate(timeout=10)
    assert "vehicle 2 of 3: Simulated PX4 multirotor (sysid 2)" in out
    assert f"API link  udp 127.0.0.1:{api_port + 1} -> 127.0.0.1:{api_remote + 1}" in out
    assert "sysid 2: Armed by external command" in out and "sysid 1: Armed" not in out


@contextlib.contextmanager
def fleet_of_three():
    api_base, api_remote_base, gcs_base, gcs_remote = free_udp_ports(4)
    vehicles = [(config, UdpPorts(api_port=api_base + 100 + k, api_remote_port=api_remote_base + 200 + k,
                                  gcs_port=gcs_base + 300 + k, gcs_remote_port=gcs_remote))
                for k, config in enumerate(fleet_configs(VehicleConfig(seed=4), 3, offset_line=(90.0, 40.0)))]
    with VehicleServer.fleet(vehicles, speed=SPEED) as server:
        yield server, gcs_remote


@pytest.mark.slow
@pytest.mark.mavsdk
def test_mavsdk_finds_every_vehicle_on_the_gcs_port_and_flies_vehicle_2():
    pytest.importorskip("mavsdk.asyncio")
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.action import ActionAsync
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

    async def fly(gcs_port: int, server: VehicleServer) -> None:
        drone = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
        try:
            await asyncio.wait_for(drone.add_any_connection(f"udpin://0.0.0.0:{gcs_port}"), 10)
            deadline = time.monotonic() + 15
            while await drone.system_count() < 3 and time.monotonic() < deadline:
                await asyncio.sleep(0.2)
            systems = {await system.get_system_id(): system for system in await drone.get_systems()}
            assert set(systems) == {1, 2, 3}
            action, telemetry = ActionAsync(systems[2]), TelemetryAsync(systems[2])
            async with contextlib.aclosing(telemetry.subscribe_health()) as health:
                async def ready():
                    async for item in health:
                        if item.is_global_position_ok and item.is_home_position_ok:
                            return
                await asyncio.wait_for(ready(), 20)
            await asyncio.wait_for(action.set_takeoff_altitude(8.0), 10)
            await asyncio.wait_for(action.arm(), 10)
            await asyncio.wait_for(action.takeoff(), 10)
            deadline = time.monotonic() + 20
            while -server.vehicles[1].state.down_m < 7.0 and time.monotonic() < deadline:
                await asyncio.sleep(0.1)
        finally:
            drone.destroy()

    with fleet_of_three() as (server, gcs_port):
        asyncio.run(fly(gcs_port, server))
        first, second, third = server.vehicles
        assert second.autopilot.armed and -second.state.down_m > 7.0
        assert not first.autopilot.armed and not third.autopilot.armed
        assert first.state.on_ground and third.state.on_ground


@pytest.mark.slow
def test_mavproxy_switches_between_the_vehicles(tmp_path):
    pytest.importorskip("MAVProxy")
    from test_mavproxy_flight import MavProxy, wait_until

    with fleet_of_three() as (server, gcs_port):
        mavproxy = MavProxy(f"udpin:0.0.0.0:{gcs_port}", tmp_path)
        try:
            for system in (1, 2, 3):
                mavproxy.expect(f"Detected vehicle {system}:1", timeout_s=15)
            mavproxy.send("vehicle 3")
            mavproxy.expect("Set vehicle 3")
            mavproxy.send("arm throttle")
            wait_until(lambda: server.vehicles[2].autopilot.armed, 10, "vehicle 3 armed")
            assert not server.vehicles[0].autopilot.armed and not server.vehicles[1].autopilot.armed
            mavproxy.send("vehicle 1")
            mavproxy.expect("Set vehicle 1")
            mavproxy.send("arm throttle")
            wait_until(lambda: server.vehicles[0].autopilot.armed, 10, "vehicle 1 armed")
            assert not server.vehicles[1].autopilot.armed
        finally:
            mavproxy.close()
