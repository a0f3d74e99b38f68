"""One UDP port carrying several vehicles, as a ground station's 14550 does.

PX4 SITL instance N sends its ground-station link from port 18570+N to 14550, ArduPilot's instances send theirs
to 14550 as well, and QGroundControl listens there once and tells the vehicles apart by their system ids. A fleet
runner can do the same: ``hrlsac mission run FLEET.yaml --connect udpin:0.0.0.0:14550`` (one ``udpin`` for the
whole fleet) binds the port once and gives every drone its own pymavlink connection (:meth:`SharedUdpPort.channel`).

Routing: a datagram goes to the channel of the system id in its first MAVLink frame (an autopilot sends each
datagram from one system); datagrams of other system ids, and ones that are not MAVLink, are counted and dropped.
What a channel sends goes to the address its system's datagrams come from, as a UDP ground station answers each
vehicle; before the first datagram of that system it has nowhere to go and is dropped, as pymavlink's own
``udpin`` does before it hears anyone.
"""
from __future__ import annotations

import collections
import os
import re
import socket

from pymavlink import mavutil

from autonomy.vehicle_link import LinkError

MAVLINK2_MAGIC = 0xFD
MAVLINK1_MAGIC = 0xFE
UDP_MAX_DATAGRAM = 65535


def is_shared_port(url: str) -> bool:
    """Whether ``url`` can carry a whole fleet: a ``udpin`` port, where a ground station listens."""
    return url.startswith("udpin:")


def open_shared_port(url: str) -> SharedUdpPort:
    """Bind ``udpin:HOST:PORT`` for a fleet (a one-line LinkError when it cannot be)."""
    match = re.fullmatch(r"udpin:([^:]+):(\d{1,5})", url)
    if match is None or not 0 < int(match[2]) < 65536:
        raise LinkError(f"cannot use connection {url!r} for a fleet: write udpin:HOST:PORT (a ground station's "
                        "port, e.g. udpin:0.0.0.0:14550), or give one --connect per drone")
    # MAVLink 2 from the first byte, the common dialect: as autonomy.vehicle_link.open_connection speaks
    os.environ.setdefault("MAVLINK20", "1")
    mavutil.set_dialect("common")
    try:
        return SharedUdpPort(match[1], int(match[2]))
    except OSError as exc:
        raise LinkError(f"cannot open connection {url!r}: {exc.strerror or exc}") from None


def frame_system_id(datagram: bytes) -> int | None:
    """The sender's system id in the first MAVLink frame of ``datagram`` (v2: byte 5, v1: byte 3); None when it
    does not start with a MAVLink frame header."""
    if len(datagram) >= 10 and datagram[0] == MAVLINK2_MAGIC:
        return datagram[5]
    if len(datagram) >= 6 and datagram[0] == MAVLINK1_MAGIC:
        return datagram[3]
    return None


class SharedUdpPort:
    """A bound UDP socket whose datagrams are routed to one channel per system id (module docstring)."""

    def __init__(self, host: str, port: int):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, port))
        self.sock.setblocking(False)
        self.address = f"udpin:{host}:{port}"
        self._inboxes: dict[int, collections.deque] = {}
        self._senders: dict[int, tuple[str, int]] = {}
        self.dropped = 0
        """Datagrams of no channel's system id, or not MAVLink."""

    def channel(self, system_id: int, source_component: int) -> SystemChannel:
        """The pymavlink connection to vehicle ``system_id``; we send as ``system_id``/``source_component`` (a
        companion computer shares its vehicle's system id)."""
        if system_id in self._inboxes:
            raise ValueError(f"{self.address} already has a channel for system id {system_id}")
        self._inboxes[system_id] = collections.deque()
        return SystemChannel(self, system_id, source_component)

    def pump(self) -> None:
        """Read every datagram waiting and file it under its system id."""
        while True:
            try:
                data, address = self.sock.recvfrom(UDP_MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return
            except ConnectionRefusedError:  # a late ICMP error for an earlier sendto; not a datagram
                continue
            system_id = frame_system_id(data)
            inbox = self._inboxes.get(system_id)
            if inbox is None:
                self.dropped += 1
                continue
            self._senders[system_id] = address
            inbox.append(data)

    def take(self, system_id: int) -> list[bytes]:
        self.pump()
        inbox = self._inboxes[system_id]
        chunks = list(inbox)
        inbox.clear()
        return chunks

    def send(self, system_id: int, data: bytes) -> None:
        address = self._senders.get(system_id)
        if address is not None:
            try:
                self.sock.sendto(data, address)
            except OSError:  # the vehicle's port is gone for now: UDP loses it, as it would on the way
                pass

    def release(self, system_id: int) -> None:
        """Forget ``system_id``'s channel; the port closes with its last channel."""
        self._inboxes.pop(system_id, None)
        if not self._inboxes:
            self.sock.close()

    def close(self) -> None:
        self.sock.close()


class SystemChannel(mavutil.mavfile):
    """One vehicle's pymavlink connection on a :class:`SharedUdpPort` (non-blocking). Closing the last channel
    closes the port."""

    def __init__(self, port: SharedUdpPort, system_id: int, source_component: int):
        self.port, self.system_id = port, system_id
        self._pending = bytearray()
        super().__init__(None, f"{port.address}#{system_id}", source_system=system_id,
                         source_component=source_component)

    def recv(self, n: int | None = None) -> bytes:
        for chunk in self.port.take(self.system_id):
            self._pending += chunk
        if n is None:
            n = len(self._pending)
        data, self._pending = bytes(self._pending[:n]), self._pending[n:]
        return data

    def write(self, buf: bytes) -> None:
        self.port.send(self.system_id, buf)

    def close(self) -> None:
        self.port.release(self.system_id)
