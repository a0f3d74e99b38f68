"""What the MAVSDK tests share (tests/test_mavsdk_*.py): bounded awaits on MAVSDK's asyncio API (the ``mavsdk``
package, 4.x), MAVSDK listening until it sees the autopilot, a vehicle served over real UDP at 2x real time, and
the ArduPilot stream rates a companion link needs. Import it after ``pytest.importorskip("mavsdk.asyncio")``. Not a
test module (pytest does not collect it).
"""
from __future__ import annotations

import asyncio
import contextlib

from mavsdk.asyncio import ComponentType, Configuration, Mavsdk

from sitl_bridge.server import UdpPorts, VehicleServer
from sitl_bridge.vehicle import VehicleConfig


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


def vehicle_server(udp_ports: list[int], seed: int, autopilot: str = "px4",
                   params: dict[str, float] | None = None) -> tuple[VehicleServer, int]:
    """A vehicle whose API link talks to MAVSDK on the second port (not started); returns it and that port."""
    api_port, mavsdk_port = udp_ports[:2]
    config = VehicleConfig(seed=seed, autopilot=autopilot, params=params or {})
    ports = UdpPorts(api_port=api_port, api_remote_port=mavsdk_port, gcs_remote_port=None)
    return VehicleServer(config, ports, speed=SPEED), mavsdk_port


# ArduCopter streams nothing until asked (SRn_* = 0) and MAVSDK asks ArduPilot for no stream: its health flags come
# from SYS_STATUS alone (MAVSDK telemetry_impl.cpp, process_sys_status). ArduPilot's documented fix for a companion
# computer is to set the link's SRx_ parameters (ardupilot.org/dev/docs/mavlink-requesting-data.html); docs/sitl.md.
COMPANION_STREAMS = {"SR0_EXT_STAT": 2.0, "SR0_POSITION": 5.0, "SR0_EXTRA1": 4.0}  # the API link is link 0 here
