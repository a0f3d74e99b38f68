"""Running the simulated vehicle in real time over UDP, PX4-SITL style.

PX4 SITL opens two MAVLink instances: the API/offboard link (local port 14580, sending to 14540, where
MAVSDK listens with ``udpin://0.0.0.0:14540``) and the GCS link (local port 18570, sending to 14550, where
QGroundControl and MAVProxy listen). We do the same; each link also answers any peer that writes to it.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Callable

from missions.signing import wall_timestamp
from sitl_bridge.autopilot import AutopilotEvent
from sitl_bridge.clock import WallClock
from sitl_bridge.faults import LinkFaults, apply_faults, wall_clock_since_now
from sitl_bridge.link import UdpLink
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


class VehicleServer:
    """A :class:`SimulatedVehicle` ticking in real time (times ``speed``) over UDP, in a thread or the foreground."""

    def __init__(self, config: VehicleConfig | None = None, ports: UdpPorts = UdpPorts(), speed: float = 1.0,
                 on_event: Callable[[AutopilotEvent], None] | None = None, link_faults: LinkFaults | None = None):
        """``link_faults``: injected on every link, timed on the wall clock from now, seeded by the vehicle's seed
        (plus the link's index) unless they carry their own seed."""
        self.clock = WallClock(speed)
        self.links = [UdpLink("api", (ports.host, ports.api_port), (ports.host, ports.api_remote_port))]
        if ports.gcs_remote_port is not None:
            try:
                self.links.append(UdpLink("gcs", (ports.host, ports.gcs_port), (ports.host, ports.gcs_remote_port)))
            except OSError:
                self.links[0].close()
                raise
        seed = (config or VehicleConfig()).seed
        self.faulty_links = apply_faults(self.links, link_faults, wall_clock_since_now(), seed)
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
