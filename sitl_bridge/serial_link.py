"""The simulated vehicle on a serial line: a tty device, or a pseudo-terminal a client opens like a telemetry radio.

A companion computer usually reaches its autopilot over a UART (``hrlsac mission run --connect
serial:/dev/ttyAMA0:921600``). :class:`SerialLink` gives the vehicle the same kind of link (the :class:`Link`
interface of :mod:`sitl_bridge.link`): a byte stream (``stream`` True: a MAVLink frame may arrive in pieces), read
and written without blocking on a file descriptor in raw mode.

* :func:`open_pty_link`: a pseudo-terminal pair; the vehicle keeps the master end, a client opens the slave's path
  (``/dev/pts/N``) as its serial device. No baud rate applies: a pty moves bytes as fast as both ends read them.
* :func:`open_serial_link`: a real serial device at a baud rate (a USB-serial adapter looped to the companion
  computer's UART, for a bench test of the wiring).

Like a UART whose transmit buffer is full, a write that does not fit is dropped (a frame may be cut; the reader's
MAVLink parser resynchronises on the next start byte): the vehicle never waits for a client that does not read.
POSIX only (termios).
"""
from __future__ import annotations

import errno
import os
import termios
import tty

READ_CHUNK = 4096


class SerialLink:
    """One end of a serial line on the file descriptor ``fd`` (raw mode, non-blocking), owned by the link.
    ``device``: the path a client opens to talk to the vehicle; ``keep_open``: further descriptors closed with it
    (a pty's slave end, held so the line stays up while no client has it open)."""

    stream = True

    def __init__(self, name: str, fd: int, device: str, keep_open: tuple[int, ...] = ()):
        self.name = name
        self.fd = fd
        self.device = device
        self._keep_open = keep_open
        self.dropped_bytes = 0
        os.set_blocking(fd, False)

    def send(self, data: bytes) -> None:
        try:
            written = os.write(self.fd, data)
        except BlockingIOError:
            written = 0
        except OSError as exc:  # the device went away (EIO): like a radio out of range
            if exc.errno != errno.EIO:
                raise
            written = 0
        self.dropped_bytes += len(data) - written

    def receive(self) -> list[bytes]:
        chunks = []
        while True:
            try:
                data = os.read(self.fd, READ_CHUNK)
            except BlockingIOError:
                return chunks
            except OSError as exc:  # EIO: a pty master whose slave is closed
                if exc.errno != errno.EIO:
                    raise
                return chunks
            if not data:
                return chunks
            chunks.append(data)

    def close(self) -> None:
        for fd in (self.fd, *self._keep_open):
            try:
                os.close(fd)
            except OSError:
                pass


def open_pty_link(name: str = "serial") -> tuple[SerialLink, str]:
    """A pseudo-terminal pair in raw mode: the link on its master end, and the slave's path for the client."""
    master, slave = os.openpty()
    for fd in (master, slave):
        tty.setraw(fd)
    path = os.ttyname(slave)
    return SerialLink(name, master, path, keep_open=(slave,)), path


def open_serial_link(device: str, baud: int, name: str = "serial") -> SerialLink:
    """The serial ``device`` at ``baud`` in raw mode; OSError with one line naming the device if it cannot be."""
    speed = getattr(termios, f"B{baud}", None)
    if speed is None:
        raise OSError(f"{name} link: {baud} is not a baud rate this system's serial driver knows")
    try:
        fd = os.open(device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    except OSError as exc:
        raise OSError(f"{name} link: cannot open {device} ({exc.strerror})") from None
    try:
        tty.setraw(fd)
        attributes = termios.tcgetattr(fd)
        attributes[4] = attributes[5] = speed  # input and output speed
        termios.tcsetattr(fd, termios.TCSANOW, attributes)
    except termios.error as exc:
        os.close(fd)
        raise OSError(f"{name} link: {device} is not a serial device ({exc.args[-1]})") from None
    return SerialLink(name, fd, device)
