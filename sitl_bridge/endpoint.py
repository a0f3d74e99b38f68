"""One MAVLink link of the vehicle: its encoder/decoder, and which telemetry it streams when.

Every link has its own sequence numbers and its own stream rates, as on a real autopilot (PX4 runs one MAVLink
instance per link, ArduPilot one GCS_MAVLINK channel per serial port). The default rates come from the vehicle's
telemetry profile (:mod:`sitl_bridge.telemetry_profiles`); a client changes one message with
MAV_CMD_SET_MESSAGE_INTERVAL, or (ArduPilot) a whole stream group with REQUEST_DATA_STREAM.
"""
from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.link import Link

AUTOPILOT_COMPONENT = mavlink.MAV_COMP_ID_AUTOPILOT1


class TelemetrySchedule:
    """Per-link message intervals and the next time each message is due (on a fixed grid)."""

    def __init__(self, rates_hz: dict[int, float]):
        self.interval_s: dict[int, float] = {}
        self.next_due_s: dict[int, float] = {}
        for msg_id, rate in rates_hz.items():
            self.set_interval(msg_id, 1.0 / rate if rate > 0 else None, now=0.0)

    def set_interval(self, msg_id: int, interval_s: float | None, now: float) -> None:
        """Stream ``msg_id`` every ``interval_s`` from ``now`` on; None stops it."""
        if interval_s is None:
            self.interval_s.pop(msg_id, None)
            self.next_due_s.pop(msg_id, None)
        else:
            self.interval_s[msg_id] = interval_s
            self.next_due_s[msg_id] = now

    def due(self, now: float) -> list[int]:
        """Messages due at ``now``; advances their deadlines by one interval (or resyncs if far behind)."""
        due = []
        for msg_id, deadline in self.next_due_s.items():
            if deadline <= now + 1e-9:
                due.append(msg_id)
                interval = self.interval_s[msg_id]
                deadline += interval
                self.next_due_s[msg_id] = deadline if deadline > now else now + interval
        return due


class _LinkWriter:
    """The ``file`` pymavlink's encoder writes to: forwards each packed message to the link."""

    def __init__(self, link: Link):
        self.write = link.send


class Endpoint:
    """One link with its own MAVLink encoder/decoder (sequence numbers) and telemetry schedule."""

    def __init__(self, link: Link, system_id: int, rates_hz: dict[int, float], index: int = 0):
        """``rates_hz``: the link's default rate of every streamed message (0 = off); ``index``: the link's place
        in the vehicle's link list (ArduPilot's SRn_ parameters, the signing link id)."""
        self.link = link
        self.index = index
        self.mav = mavlink.MAVLink(_LinkWriter(link), srcSystem=system_id, srcComponent=AUTOPILOT_COMPONENT)
        self.mav.robust_parsing = True  # malformed bytes become BAD_DATA messages, not exceptions
        self.default_rates_hz = dict(rates_hz)
        self.schedule = TelemetrySchedule(rates_hz)
        self.bad_frames = 0

    def send(self, msg: mavlink.MAVLink_message) -> None:
        self.mav.send(msg)

    def parse(self, data: bytes) -> list[mavlink.MAVLink_message]:
        """The messages in one received chunk. Datagram links carry whole frames per datagram (UDP, the memory
        link), so bytes left over are a damaged frame: dropped and counted, never allowed to swallow the next
        datagram (a garbage header claiming 255 bytes would otherwise eat the following valid command). On a
        stream link (TCP) a frame may continue in the next chunk, so the rest is kept."""
        messages = self.mav.parse_buffer(data) or []
        if self.mav.buf_len() and not getattr(self.link, "stream", False):
            self.bad_frames += 1
            self.mav.buf, self.mav.buf_index = bytearray(), 0
            self.mav.expected_length = mavlink.HEADER_LEN_V1 + 2
        return messages

    def set_message_interval(self, msg_id: int, interval_us: float, now: float, min_interval_s: float) -> bool:
        """MAV_CMD_SET_MESSAGE_INTERVAL for a message the vehicle can build: 0 restores the link's default rate,
        < 0 stops it, > 0 streams every ``interval_us`` (at most once a physics tick). False: refused (non-finite)."""
        if not math.isfinite(interval_us):
            return False
        if interval_us == 0:  # back to the default rate
            rate = self.default_rates_hz.get(msg_id, 0.0)
            self.schedule.set_interval(msg_id, 1.0 / rate if rate > 0 else None, now)
        elif interval_us < 0:
            self.schedule.set_interval(msg_id, None, now)
        else:
            self.schedule.set_interval(msg_id, max(interval_us * 1e-6, min_interval_s), now)
        return True

    def set_stream_rate(self, msg_ids: tuple[int, ...], rate_hz: float, now: float) -> None:
        """REQUEST_DATA_STREAM (ArduPilot): the messages of one group now stream at ``rate_hz`` (0 stops them)."""
        for msg_id in msg_ids:
            self.default_rates_hz[msg_id] = rate_hz
            self.schedule.set_interval(msg_id, 1.0 / rate_hz if rate_hz > 0 else None, now)
