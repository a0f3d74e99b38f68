"""Running the simulated vehicle in real time over UDP (and TCP), PX4-SITL or ArduPilot-SITL style.

PX4 SITL opens two MAVLink instances: the API/offboard link (local port 14580, sending to 14540, where
MAVSDK listens with ``udpin://0.0.0.0:14540``) and the GCS link (local port 18570, sending to 14550, where
QGroundControl and MAVProxy listen). We do the same; each link also answers any peer that writes to it.

ArduPilot's SITL binary serves MAVLink on TCP 5760 (SERIAL0), and sim_vehicle.py starts MAVProxy on it with
``--out 127.0.0.1:14550 --out 127.0.0.1:14551`` (a ground station and a companion script listen there). The
ArduPilot personality's closest equivalent (:meth:`UdpPorts.for_autopilot`): TCP 5760, and two UDP links that
send to 14550 (GCS) and 14551 (companion) themselves, from local ports 14560 and 14561.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Callable

from mavlink_signing import wall_timestamp
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
        if autopilot == "ardupilot":
            return cls(host, api_port=14561, api_remote_port=14551, gcs_port=14560, gcs_remote_port=14550,
                       tcp_port=5760)
        return cls(host)


class VehicleServer:
    """A :class:`SimulatedVehicle` ticking in real time (times ``speed``) over UDP/TCP, in a thread or the
    foreground."""

    def __init__(self, config: VehicleConfig | None = None, ports: UdpPorts = UdpPorts(), speed: float = 1.0,
                 on_event: Callable[[AutopilotEvent], None] | None = None, link_faults: LinkFaults | None = None,
                 extra_links: tuple[Link, ...] = ()):
        """``link_faults``: injected on every UDP link, timed on the wall clock from now, seeded by the vehicle's
        seed (plus the link's index) unless they carry their own seed. Link order (ArduPilot's SRn_ index, the
        signing link id): API then GCS without a TCP port (PX4), else TCP, GCS, API (ArduPilot); then
        ``extra_links`` (a serial line: sitl_bridge.serial_link), which the server closes with the others."""
        self.clock = PacedClock(speed)
        order = ("tcp", "gcs", "api") if ports.tcp_port is not None else ("api", "gcs")
        self.links: list[Link] = []
        try:
            for name in order:
                if name == "tcp":
                    self.links.append(TcpServerLink("tcp", (ports.host, ports.tcp_port)))
                elif name == "gcs" and ports.gcs_remote_port is not None:
                    self.links.append(UdpLink("gcs", (ports.host, ports.gcs_port), (ports.host, ports.gcs_remote_port)))
                elif name == "api":
                    self.links.append(UdpLink("api", (ports.host, ports.api_port), (ports.host, ports.api_remote_port)))
        except OSError:
            for link in (*self.links, *extra_links):
                link.close()
            raise
        self.links.extend(extra_links)
        seed = (config or VehicleConfig()).seed
        udp = [link for link in self.links if not link.stream]
        faulty = iter(apply_faults(udp, link_faults, wall_clock_since_now(), seed))
        self.faulty_links = [link if link.stream else next(faulty) for link in self.links]
        # Real clients (pymavlink, MAVSDK, QGroundControl) sign with the wall clock: so must we.
        self.vehicle = SimulatedVehicle(config, self.faulty_links, on_event=on_event,
                                        signing_timestamp=wall_timestamp)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None

    def serve(self) -> None:
        """Tick until :meth:`stop` (or Ctrl-C in the foreground)."""
        self.clock.start()
        vehicle = self.vehicle
        try:
            while not self._stop.is_set():
                vehicle.step()
                self.clock.pace(vehicle.time_s)
        except BaseException as exc:  # keep the reason for whoever joins the thread
            self.error = exc
            raise
        finally:
            for link in self.links:
                link.close()

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
