"""Running the simulated vehicle in real time over UDP (and TCP), PX4-SITL or ArduPilot-SITL style.

PX4 SITL opens two MAVLink instances: the API/offboard link (local port 14580, sending to 14540, where
MAVSDK listens with ``udpin://0.0.0.0:14540``) and the GCS link (local port 18570, sending to 14550, where
QGroundControl and MAVProxy listen). We do the same; each link also answers any peer that writes to it.

ArduPilot's SITL binary serves MAVLink on TCP 5760 (SERIAL0), and sim_vehicle.py starts MAVProxy on it with
``--out 127.0.0.1:14550 --out 127.0.0.1:14551`` (a ground station and a companion script listen there). The
ArduPilot personality's closest equivalent (:meth:`UdpPorts.for_autopilot`): TCP 5760, and two UDP links that
send to 14550 (GCS) and 14551 (companion) themselves, from local ports 14560 and 14561.

Several vehicles run in one process as the autopilots' own SITL scripts number their instances
(:meth:`UdpPorts.for_instance`, :func:`fleet_configs`): PX4's instance N speaks as system N + 1 (``param set
MAV_SYS_ID $((px4_instance+1))`` in ``ROMFS/px4fmu_common/init.d-posix/rcS``) with its API link on 14580+N -> 14540+N
(14549 from N = 10) and its GCS link on 18570+N -> 14550 (``px4-rc.mavlink``): every instance talks to the one
ground-station port, where QGroundControl and MAVProxy tell the vehicles apart by system id. ArduPilot's
``sim_vehicle.py -I N`` moves every port of instance N up by 10 (TCP 5760+10N), and ``--auto-sysid`` gives it system
N + 1; here its GCS link also sends to 14550 and its companion link to 14551+10N.
"""
from __future__ import annotations

import dataclasses
import math
import threading
from dataclasses import dataclass
from typing import Callable, Sequence

from mavlink_signing import wall_timestamp
from missions.geodesy import GeoPoint, LocalFrame
from sitl_bridge.autopilot_base import AutopilotEvent
from sitl_bridge.clock import PacedClock
from sitl_bridge.faults import LinkFaults, apply_faults, wall_clock_since_now
from sitl_bridge.link import Link, TcpServerLink, UdpLink
from sitl_bridge.vehicle import SimulatedVehicle, VehicleConfig


@dataclass(frozen=True)
class UdpPorts:
    """Where the two MAVLink links bind and whom they send to by default."""

    host: str = "127.0.0.1"
    """Address to bind and default destination host."""
    api_port: int = 14580
    """Local port of the API/offboard link."""
    api_remote_port: int = 14540
    """Where the API link sends (MAVSDK's default)."""
    gcs_port: int = 18570
    """Local port of the ground-station link."""
    gcs_remote_port: int | None = 14550
    """Where the GCS link sends (QGroundControl / MAVProxy default); None disables the GCS link."""
    tcp_port: int | None = None
    """A TCP server port (ArduPilot SITL's SERIAL0 is 5760); None: no TCP link."""

    @classmethod
    def for_autopilot(cls, autopilot: str, host: str = "127.0.0.1") -> "UdpPorts":
        """The default ports of a personality: PX4 SITL's, or the ArduPilot SITL equivalent described above."""
        return cls.for_instance(autopilot, 0, host)

    @classmethod
    def for_instance(cls, autopilot: str, instance: int, host: str = "127.0.0.1") -> "UdpPorts":
        """The ports of SITL instance ``instance`` (from 0) of a personality, as described above."""
        if autopilot == "ardupilot":
            step = 10 * instance
            return cls(host, api_port=14561 + step, api_remote_port=14551 + step, gcs_port=14560 + step,
                       gcs_remote_port=14550, tcp_port=5760 + step)
        return cls(host, api_port=14580 + instance, api_remote_port=14540 + instance if instance <= 9 else 14549,
                   gcs_port=18570 + instance)


DEFAULT_OFFSET_LINE = {"px4": (0.0, 3.0), "ardupilot": (90.0, 10.0)}
"""Where a personality's instances stand by default, as (bearing in degrees, spacing in metres) from the first:
PX4's ``Tools/simulation/gazebo-classic/sitl_multiple_run.sh`` spawns instance N 3 m north of the one before
(``Y=$((3*N))``); ArduPilot's SITL documentation spaces a swarm with ``--auto-offset-line 90,10``."""


def fleet_configs(base: VehicleConfig, count: int, first_instance: int = 0,
                  offset_line: tuple[float, float] | None = None) -> list[VehicleConfig]:
    """The configs of ``count`` instances from ``first_instance`` on: system id instance + 1, home moved along
    ``offset_line`` (bearing in degrees, spacing in metres; default: the personality's) by its place in the
    fleet, a sensor seed of its own."""
    bearing_deg, spacing_m = offset_line or DEFAULT_OFFSET_LINE[base.autopilot]
    frame, bearing = LocalFrame(base.home), math.radians(bearing_deg)
    configs = []
    for k in range(count):
        lat, lon, alt = frame.to_geodetic(k * spacing_m * math.cos(bearing), k * spacing_m * math.sin(bearing), 0.0)
        configs.append(dataclasses.replace(base, home=GeoPoint(lat, lon, alt), system_id=first_instance + k + 1,
                                           seed=base.seed + k))
    return configs


class VehicleServer:
    """Simulated vehicles ticking together in real time (times ``speed``) over UDP/TCP, in a thread or the
    foreground: one vehicle, or a fleet (:meth:`fleet`)."""

    def __init__(self, config: VehicleConfig | None = None, ports: UdpPorts = UdpPorts(), speed: float = 1.0,
                 on_event: Callable[[AutopilotEvent], None] | None = None, link_faults: LinkFaults | None = None,
                 extra_links: tuple[Link, ...] = ()):
        """``link_faults``: injected on every UDP link, timed on the wall clock from now, seeded by the vehicle's
        seed (plus the link's index) unless they carry their own seed. Link order (ArduPilot's SRn_ index, the
        signing link id): API then GCS without a TCP port (PX4), else TCP, GCS, API (ArduPilot); then
        ``extra_links`` (a serial line: sitl_bridge.serial_link), which the server closes with the others."""
        self.clock = PacedClock(speed)
        self.vehicles: list[SimulatedVehicle] = []
        self.vehicle_links: list[list[Link]] = []
        self.faulty_links: list[Link] = []
        try:
            self._add(config or VehicleConfig(), ports, on_event, link_faults, extra_links)
        except OSError:
            for link in extra_links:
                link.close()
            raise
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None

    @classmethod
    def fleet(cls, vehicles: Sequence[tuple[VehicleConfig, UdpPorts]], speed: float = 1.0,
              on_event: Callable[[int, AutopilotEvent], None] | None = None,
              link_faults: LinkFaults | None = None) -> "VehicleServer":
        """Several vehicles, each with its config and ports, stepped together on one clock in one thread;
        ``on_event`` gets the vehicle's index in the fleet with each event."""
        def events(index: int) -> Callable[[AutopilotEvent], None] | None:
            return None if on_event is None else (lambda event: on_event(index, event))

        (first_config, first_ports), *others = vehicles
        server = cls(first_config, first_ports, speed, events(0), link_faults)
        try:
            for index, (config, ports) in enumerate(others, start=1):
                server._add(config, ports, events(index), link_faults, ())
        except OSError:
            server.close()
            raise
        return server

    def _add(self, config: VehicleConfig, ports: UdpPorts, on_event: Callable[[AutopilotEvent], None] | None,
             link_faults: LinkFaults | None, extra_links: tuple[Link, ...]) -> None:
        """Open one vehicle's links and boot it."""
        order = ("tcp", "gcs", "api") if ports.tcp_port is not None else ("api", "gcs")
        links: list[Link] = []
        try:
            for name in order:
                if name == "tcp":
                    links.append(TcpServerLink("tcp", (ports.host, ports.tcp_port)))
                elif name == "gcs" and ports.gcs_remote_port is not None:
                    links.append(UdpLink("gcs", (ports.host, ports.gcs_port), (ports.host, ports.gcs_remote_port)))
                elif name == "api":
                    links.append(UdpLink("api", (ports.host, ports.api_port), (ports.host, ports.api_remote_port)))
        except OSError:
            for link in links:
                link.close()
            raise
        links.extend(extra_links)
        udp = [link for link in links if not link.stream]
        faulty = iter(apply_faults(udp, link_faults, wall_clock_since_now(), config.seed))
        faulty_links = [link if link.stream else next(faulty) for link in links]
        # Real clients (pymavlink, MAVSDK, QGroundControl) sign with the wall clock: so must we.
        self.vehicles.append(SimulatedVehicle(config, faulty_links, on_event=on_event,
                                              signing_timestamp=wall_timestamp))
        self.vehicle_links.append(links)
        self.faulty_links.extend(faulty_links)

    @property
    def vehicle(self) -> SimulatedVehicle:
        """The (first) vehicle."""
        return self.vehicles[0]

    @property
    def links(self) -> list[Link]:
        """The links of the (first) vehicle."""
        return self.vehicle_links[0]

    def close(self) -> None:
        """Close every vehicle's links."""
        for links in self.vehicle_links:
            for link in links:
                link.close()

    def serve(self) -> None:
        """Tick until :meth:`stop` (or Ctrl-C in the foreground)."""
        self.clock.start()
        vehicles = self.vehicles
        try:
            while not self._stop.is_set():
                for vehicle in vehicles:
                    vehicle.step()
                self.clock.pace(vehicles[0].time_s)
        except BaseException as exc:  # keep the reason for whoever joins the thread
            self.error = exc
            raise
        finally:
            self.close()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def start(self) -> "VehicleServer":
        """Serve in a daemon thread."""
        self._thread = threading.Thread(target=self.serve, name="sitl-vehicle", daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout_s: float = 5.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)

    def __enter__(self) -> "VehicleServer":
        return self.start()

    def __exit__(self, *exc_info) -> None:
        self.stop()
