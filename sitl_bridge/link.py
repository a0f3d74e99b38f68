"""Byte links that carry MAVLink between the simulated vehicle and its clients.

Three kinds, one interface (``send(bytes)``, ``receive() -> list[bytes]``, ``close()``, and ``stream``: False when
every chunk is whole MAVLink frames, True for a byte stream whose frames may be split across chunks):

* :class:`UdpLink`: a real UDP socket, like PX4 SITL's. It sends to a default remote address and also
  answers every peer that has talked to it, so both ``udpin`` listeners (MAVSDK on 14540, QGroundControl
  on 14550) and ``udpout`` clients (a pymavlink script sending to our port) work.
* :class:`TcpServerLink`: a TCP server, like ArduPilot SITL's SERIAL0 on port 5760, for every client that connects.
* :class:`MemoryLink`: two in-process queues, for lockstep runs where nothing may depend on the OS.

:class:`MemoryMavConnection` wraps the client end of a memory link as a pymavlink ``mavfile``, so client
code written for ``mavutil.mavlink_connection`` works unchanged in lockstep.
"""
from __future__ import annotations

import collections
import socket
from typing import Protocol

from pymavlink import mavutil

UDP_MAX_DATAGRAM = 65535


def _bound_socket(name: str, bind: tuple[str, int], kind: int, listen: int = 0) -> socket.socket:
    """A non-blocking UDP (SOCK_DGRAM) or listening TCP (SOCK_STREAM) socket on ``bind``, or a one-line OSError."""
    sock = socket.socket(socket.AF_INET, kind)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind(bind)
        if kind == socket.SOCK_STREAM:
            sock.listen(listen)
    except OSError as exc:
        sock.close()
        what = "listen on TCP" if kind == socket.SOCK_STREAM else "bind UDP"
        raise OSError(f"{name} link: cannot {what} {bind[0]}:{bind[1]} ({exc.strerror}); "
                      "is another simulator running? choose another port") from None
    sock.setblocking(False)
    return sock


class Link(Protocol):
    """What the vehicle needs from a transport."""

    name: str
    stream: bool

    def send(self, data: bytes) -> None: ...

    def receive(self) -> list[bytes]: ...

    def close(self) -> None: ...


class MemoryLink:
    """One end of an in-memory byte pipe; see :func:`memory_link_pair`."""

    stream = False

    def __init__(self, name: str, inbox: collections.deque, outbox: collections.deque):
        self.name = name
        self._inbox = inbox
        self._outbox = outbox

    def send(self, data: bytes) -> None:
        self._outbox.append(bytes(data))

    def receive(self) -> list[bytes]:
        chunks = []
        while self._inbox:
            chunks.append(self._inbox.popleft())
        return chunks

    def close(self) -> None:
        self._inbox.clear()


def memory_link_pair(name: str = "memory") -> tuple[MemoryLink, MemoryLink]:
    """Two connected ends: what one sends, the other receives (in order, nothing lost)."""
    a_to_b: collections.deque = collections.deque()
    b_to_a: collections.deque = collections.deque()
    return MemoryLink(name, inbox=b_to_a, outbox=a_to_b), MemoryLink(name, inbox=a_to_b, outbox=b_to_a)


class UdpLink:
    """A UDP endpoint bound to ``bind`` that sends to ``remote`` and to every peer that wrote to it."""

    stream = False

    def __init__(self, name: str, bind: tuple[str, int], remote: tuple[str, int] | None, max_peers: int = 8):
        self.name = name
        self.remote = remote
        self.max_peers = max_peers
        self.peers: list[tuple[str, int]] = []  # most recent last
        self.sock = _bound_socket(name, bind, socket.SOCK_DGRAM)

    def destinations(self) -> list[tuple[str, int]]:
        if self.remote is None or self.remote in self.peers:
            return list(self.peers)
        return [self.remote, *self.peers]

    def send(self, data: bytes) -> None:
        for address in self.destinations():
            try:
                self.sock.sendto(data, address)
            except OSError:
                # Nobody listening (ICMP port unreachable) or a full buffer: UDP drops, like a radio.
                pass

    def receive(self) -> list[bytes]:
        chunks = []
        while True:
            try:
                data, address = self.sock.recvfrom(UDP_MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return chunks
            except ConnectionRefusedError:
                continue  # a late ICMP error for an earlier sendto; not a datagram
            if address not in self.peers:
                self.peers.append(address)
                del self.peers[: -self.max_peers]
            chunks.append(data)

    def close(self) -> None:
        self.sock.close()


class TcpServerLink:
    """A TCP server bound to ``bind``: what the vehicle sends goes to every connected client (at most
    ``max_clients``), what any client sends is received. A client whose socket buffer is full (it stopped
    reading) is dropped: the vehicle never waits for a client."""

    stream = True

    def __init__(self, name: str, bind: tuple[str, int], max_clients: int = 4):
        self.name = name
        self.max_clients = max_clients
        self.clients: list[socket.socket] = []
        self.sock = _bound_socket(name, bind, socket.SOCK_STREAM, listen=max_clients)

    def _accept(self) -> None:
        while len(self.clients) < self.max_clients:
            try:
                client, _ = self.sock.accept()
            except (BlockingIOError, InterruptedError):
                return
            client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            client.setblocking(False)
            self.clients.append(client)

    def _drop(self, client: socket.socket) -> None:
        self.clients.remove(client)
        client.close()

    def send(self, data: bytes) -> None:
        for client in list(self.clients):
            try:
                client.sendall(data)
            except OSError:  # gone, or not reading (BlockingIOError: its buffer is full)
                self._drop(client)

    def receive(self) -> list[bytes]:
        self._accept()
        chunks = []
        for client in list(self.clients):
            while True:
                try:
                    data = client.recv(UDP_MAX_DATAGRAM)
                except (BlockingIOError, InterruptedError):
                    break
                except OSError:
                    self._drop(client)
                    break
                if not data:  # the client closed the connection
                    self._drop(client)
                    break
                chunks.append(data)
        return chunks

    def close(self) -> None:
        for client in list(self.clients):
            self._drop(client)
        self.sock.close()


class MemoryMavConnection(mavutil.mavfile):
    """A pymavlink connection over one end of a memory link (non-blocking; the caller steps the vehicle)."""

    def __init__(self, link: MemoryLink, source_system: int = 255, source_component: int = 190):
        self.link = link
        self._pending = bytearray()
        super().__init__(None, f"memory:{link.name}", source_system=source_system,
                         source_component=source_component)

    def recv(self, n: int | None = None) -> bytes:
        for chunk in self.link.receive():
            self._pending += chunk
        if n is None:
            n = len(self._pending)
        data, self._pending = bytes(self._pending[:n]), self._pending[n:]
        return data

    def recv_msg(self):
        """pymavlink's receive, returning at once when nothing arrived and nothing is part-parsed (the runner asks
        every tick, and most ticks bring nothing)."""
        if not self._pending and self.mav.buf_len() == 0:
            for chunk in self.link.receive():
                self._pending += chunk
            if not self._pending:
                return None
        return super().recv_msg()

    def write(self, buf: bytes) -> None:
        self.link.send(buf)

    def close(self) -> None:
        self.link.close()
