"""The companion computer's MAVLink side: one pymavlink connection to the autopilot.

:func:`open_connection` turns a URL into a pymavlink connection (``udpin:HOST:PORT``, ``udpout:HOST:PORT``,
``tcp:HOST:PORT``, ``serial:DEVICE[:BAUD]`` or a bare device path); lockstep replays pass an in-memory
connection instead. :class:`VehicleLink` then does what every companion computer does and nothing more:

* identifies itself with a HEARTBEAT (type ONBOARD_CONTROLLER, autopilot INVALID) once per second;
* discovers the vehicle from the first autopilot HEARTBEAT and addresses everything to it;
* keeps what the runner reads: the latest message of each type, the flight mode (PX4 custom modes, decoded by
  pymavlink), the time of the last vehicle message (telemetry loss), COMMAND_ACKs and STATUSTEXTs;
* sends COMMAND_LONG, SET_MESSAGE_INTERVAL and velocity setpoints, and reads the parameters it is asked for;
* hands every message, both directions, to an optional recorder (the tlog) with the run's clock;
* with a signing key, signs everything it sends (timestamps from the run's clock), drops wrongly signed and
  replayed messages, and warns once when the vehicle's messages arrive unsigned (see mavlink_signing).

It does not wait for anything itself: the runner owns time (simulated in lockstep, real otherwise) and waits by
ticking; see ``autonomy.runner_core``.
"""
from __future__ import annotations

import math
import os
import re
import struct
from collections import deque
from dataclasses import dataclass, field
from typing import Callable, Protocol

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from autonomy.setpoints import VelocityCommand, setpoint_message_args
from autonomy.vehicle_connection import MAX_STATUS_TEXTS, CommandAck, first_ack, texts_after
from missions.geodesy import GeoPoint
from mavlink_signing import MAVLINK1, SIGNED, UNSIGNED, LinkSigning, simulated_timestamp

COMPANION_COMPONENT = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER
HEARTBEAT_PERIOD_S = 1.0
STATUSTEXT_LEN = 50  # bytes of STATUSTEXT.text; longer texts come in chunks
MAX_STATUSTEXT_CHARS = 1000  # a joined text is cut here
INTEGER_PARAM_TYPES = (mavlink.MAV_PARAM_TYPE_INT8, mavlink.MAV_PARAM_TYPE_UINT8, mavlink.MAV_PARAM_TYPE_INT16,
                       mavlink.MAV_PARAM_TYPE_UINT16, mavlink.MAV_PARAM_TYPE_INT32, mavlink.MAV_PARAM_TYPE_UINT32)
_URL = re.compile(r"^(udpin|udpout|tcp):[^:]+:\d{1,5}$")
_NOT_A_VEHICLE = {mavlink.MAV_TYPE_GCS, mavlink.MAV_TYPE_ONBOARD_CONTROLLER}


class LinkError(RuntimeError):
    """The connection cannot be opened or the vehicle misbehaves; one line naming the problem."""


class Recorder(Protocol):
    def record(self, time_s: float, data: bytes) -> None: ...


def enum_name(enum: str, value: int) -> str:
    """The name of a MAVLink enum value; the number itself for values this dialect does not know (a vehicle may
    send anything: a message from a newer or broken autopilot must not crash the runner)."""
    entry = mavlink.enums[enum].get(value)
    return entry.name if entry is not None else f"{enum} {value}"


def open_connection(url: str, system_id: int = 1):
    """A pymavlink connection for ``url`` as the companion computer (``system_id``, component 191)."""
    target = url
    if url.startswith("serial:"):
        parts = url[len("serial:"):].rsplit(":", 1)
        target = parts[0] if len(parts) == 1 or not parts[1].isdigit() else f"{parts[0]},{parts[1]}"
    elif not (_URL.match(url) or url.startswith("/dev/") or url.upper().startswith("COM")):
        raise LinkError(f"cannot use connection {url!r}: write udpin:HOST:PORT (listen, e.g. udpin:0.0.0.0:14540 "
                        "for PX4 SITL), udpout:HOST:PORT, tcp:HOST:PORT or serial:DEVICE[:BAUD]")
    # MAVLink 2 from the first byte. Otherwise pymavlink starts in MAVLink 1 and, on the vehicle's first MAVLink 2
    # frame, replaces its encoder with a new one, dropping whatever signing was set up on the old one.
    os.environ.setdefault("MAVLINK20", "1")
    try:
        return mavutil.mavlink_connection(target, source_system=system_id, source_component=COMPANION_COMPONENT,
                                          dialect="common", autoreconnect=True)
    except OSError as exc:
        raise LinkError(f"cannot open connection {url!r}: {exc.strerror or exc}") from None


@dataclass
class VehicleLink:
    """The pymavlink :class:`autonomy.vehicle_connection.VehicleConnection`; see the module docstring. ``clock()`` is
    the run's time in seconds."""

    conn: mavutil.mavfile
    clock: Callable[[], float]
    recorder: Recorder | None = None
    target_system: int | None = None
    target_component: int = 1
    latest: dict[str, object] = field(default_factory=dict)
    """The most recent message of each type from the vehicle."""
    last_vehicle_message_s: float | None = None
    acks: deque = field(default_factory=lambda: deque(maxlen=64))
    status_texts: list[str] = field(default_factory=list)
    status_log: deque = field(default_factory=lambda: deque(maxlen=MAX_STATUS_TEXTS))
    """(receive time, text) of the latest STATUSTEXTs; ``status_count`` counts all ever received."""
    status_count: int = 0
    sent_heartbeats: int = 0
    signing_key: bytes | None = field(default=None, repr=False)
    """MAVLink 2 signing secret (32 bytes); None: send unsigned, accept everything."""
    signing_timestamp: Callable[[], int] | None = None
    """Signing clock (10 us units since 2015); default: ``clock`` from the MAVLink epoch (lockstep replays).
    Flights in real time pass mavlink_signing.wall_timestamp, as real autopilots expect."""
    warn: Callable[[str], None] = lambda text: None
    """Where warnings go (the runner's log)."""
    signing: LinkSigning | None = field(default=None, init=False)
    _warned_unsigned: bool = field(default=False, init=False)
    _statustext_parts: dict = field(default_factory=dict, init=False)  # the chunked STATUSTEXT being joined
    params: dict[str, float] = field(default_factory=dict, init=False)
    """The parameters read with :meth:`request_params`, by name, as numbers (PX4's bytewise integers decoded)."""
    _params_wanted: set = field(default_factory=set, init=False)
    _vehicle_signs: bool = field(default=False, init=False)
    _next_heartbeat_s: float = -math.inf  # the first tick sends and anchors the 1 Hz schedule
    _home_read: tuple = field(default=(None, None), init=False)  # (HOME_POSITION message, its GeoPoint or None)
    timesync_replies: list = field(default_factory=list, init=False)
    """ts1 of the TIMESYNC replies received since the runner last took them (autonomy.uplink_probe)."""

    def __post_init__(self) -> None:
        self.conn.mav.set_send_callback(self._on_send)
        self.boot_s = self.clock()
        if self.signing_key is not None:
            # The companion computer accepts unsigned messages from a vehicle that does not sign (with a warning):
            # refusing them would only lose the vehicle, and what we send is signed, so the vehicle can refuse
            # forged commands. Once a signed message arrived, unsigned ones are a downgrade and refused.
            self.signing = LinkSigning(self.signing_key, self.signing_timestamp or simulated_timestamp(self.clock),
                                       allow_unsigned=lambda msg_id: not self._vehicle_signs)
            self.signing.install(self.conn.mav)

    # ------------------------------------------------------------------ time and housekeeping
    @property
    def time_boot_ms(self) -> int:
        """Milliseconds since this link started, for the time_boot_ms field of what we send."""
        return int(round((self.clock() - self.boot_s) * 1000.0)) & 0xFFFFFFFF

    @property
    def _mav(self):
        """The connection's encoder, signing installed: pymavlink replaces its encoder when it switches protocol."""
        if self.signing is not None:
            self.signing.install(self.conn.mav)
        return self.conn.mav

    def tick(self) -> list:
        """Receive everything waiting and send the heartbeat when due; returns the messages received."""
        now = self.clock()
        if now + 1e-9 >= self._next_heartbeat_s:
            self._mav.heartbeat_send(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID,
                                     0, 0, mavlink.MAV_STATE_ACTIVE)
            self.sent_heartbeats += 1
            self._next_heartbeat_s += HEARTBEAT_PERIOD_S
            if self._next_heartbeat_s <= now:
                self._next_heartbeat_s = now + HEARTBEAT_PERIOD_S
        received = []
        while (msg := self.conn.recv_msg()) is not None:
            if msg.get_type() == "BAD_DATA":
                continue
            self._forget_pymavlink_state(msg)
            if self.recorder is not None:
                self.recorder.record(now, bytes(msg.get_msgbuf()))
            verdict = self._signing_verdict(msg)
            if verdict is not None and self._accept(msg, now):
                received.append(msg)
                if verdict in (UNSIGNED, MAVLINK1) and not self._warned_unsigned:
                    self._warned_unsigned = True
                    self.warn(f"warning: signing is on but the vehicle's messages arrive unsigned (first: "
                              f"{msg.get_type()}); they are not authenticated: give the vehicle the same key")
        return received

    def _signing_verdict(self, msg) -> str | None:
        """The signing verdict of a received message: None when rejected (wrong key, replayed, or unsigned once the
        vehicle has signed), "" without signing."""
        if self.signing is None:
            return ""
        accepted, verdict = self.signing.admit(msg.get_msgbuf(), msg.get_msgId(), msg.get_type())
        if verdict == SIGNED:
            self._vehicle_signs = True
        return verdict if accepted else None

    def _accept(self, msg, now: float) -> bool:
        """Keep the vehicle's messages (discovering it from its first autopilot heartbeat)."""
        source = msg.get_srcSystem()
        if self.target_system is None:
            # The autopilot is component 1 (PX4 and ArduPilot): a heartbeat from another component (a ground
            # station, a camera, a fuzzer's odd frame) must not become "the vehicle".
            if msg.get_type() != "HEARTBEAT" or msg.autopilot == mavlink.MAV_AUTOPILOT_INVALID \
                    or msg.type in _NOT_A_VEHICLE or msg.get_srcComponent() != mavlink.MAV_COMP_ID_AUTOPILOT1:
                return False
            self.target_system, self.target_component = source, msg.get_srcComponent()
            self.conn.mav.srcSystem = source  # a companion computer shares its vehicle's system id
        if source != self.target_system:
            return False
        if msg.get_msgId() != mavlink.MAVLINK_MSG_ID_UNKNOWN:  # 16 million possible ids: keep only known types
            self.latest[msg.get_type()] = msg
        self.last_vehicle_message_s = now
        if msg.get_type() == "COMMAND_ACK":
            self.acks.append(CommandAck(msg.command, msg.result, now))
        elif msg.get_type() == "PARAM_VALUE" and msg.param_id in self._params_wanted:
            self.params[msg.param_id] = self._param_number(msg)
        elif msg.get_type() == "TIMESYNC" and msg.tc1 != 0:  # a reply (tc1 = 0 is the vehicle's own request)
            self.timesync_replies.append(msg.ts1)
            del self.timesync_replies[:-1000]
        elif msg.get_type() == "STATUSTEXT":
            for text in self._join_statustext(msg):
                self.status_texts.append(text)
                del self.status_texts[:-MAX_STATUS_TEXTS]
                self.status_log.append((now, text))
                self.status_count += 1
        return True

    def _join_statustext(self, msg) -> list[str]:
        """The texts a STATUSTEXT completes (none while a chunked one goes on). MAVLink: id 0 is a text of one
        message; chunks of a longer one share an id, and the chunk shorter than the 50-byte field is the last.
        PX4 gives every text an id and sends nothing after a full last chunk (STATUSTEXT.hpp), so a text waiting
        for more is also complete when another id starts (and then comes before it). PX4's ids count from 0 per
        link (``_id++``, wrapping at 65536), so from PX4 an id of 0 is chunked like any other."""
        text_id = msg.id
        parts = self._statustext_parts
        done = [parts["text"]] if parts and parts["id"] != text_id else []
        if not text_id and self.autopilot != mavlink.MAV_AUTOPILOT_PX4:
            self._statustext_parts = {}
            return done + [msg.text]
        if parts.get("id") != text_id:
            parts = self._statustext_parts = {"id": text_id, "text": ""}
        parts["text"] = (parts["text"] + msg.text)[:MAX_STATUSTEXT_CHARS]  # a hostile vehicle must not grow memory
        if len(msg.text.encode()) >= STATUSTEXT_LEN:
            return done
        self._statustext_parts = {}
        return done + [parts["text"]]

    def _forget_pymavlink_state(self, msg) -> None:
        """pymavlink's connection keeps the last message of every type per system and every parameter it hears;
        garbage (any frame with an unknown id is "decoded": its CRC cannot be checked) and hostile PARAM_VALUEs
        would grow these without bound. The runner uses neither: drop them."""
        if msg.get_msgId() == mavlink.MAVLINK_MSG_ID_UNKNOWN:
            for state in self.conn.sysid_state.values():
                state.messages.pop(msg.get_type(), None)
        elif msg.get_type() == "PARAM_VALUE":
            self.conn.param_state.clear()

    def _on_send(self, msg) -> None:
        if self.recorder is not None:
            self.recorder.record(self.clock(), bytes(msg.get_msgbuf()))

    # ------------------------------------------------------------------ what the runner reads
    @property
    def discovered(self) -> bool:
        return self.target_system is not None

    @property
    def companion_system_id(self) -> int:
        """This computer's MAVLink system id (the vehicle's, once discovered: see ``_on_message``)."""
        return self.conn.mav.srcSystem

    @property
    def flight_mode(self) -> str | None:
        """Mode name of the latest HEARTBEAT as pymavlink spells it for its autopilot ("OFFBOARD", "LOITER", "RTL",
        ... for PX4; "GUIDED", "RTL", "BRAKE", ... for ArduPilot Copter), None before one arrived."""
        beat = self.latest.get("HEARTBEAT")
        return None if beat is None else mavutil.mode_string_v10(beat)

    @property
    def autopilot(self) -> int | None:
        """The vehicle's MAV_AUTOPILOT (from its first HEARTBEAT), None before discovery."""
        beat = self.latest.get("HEARTBEAT")
        return None if beat is None else beat.autopilot

    def status_since(self, count: int) -> list[tuple[float, str]]:
        return texts_after(self.status_log, self.status_count, count)

    @property
    def armed(self) -> bool:
        beat = self.latest.get("HEARTBEAT")
        return bool(beat is not None and beat.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)

    def vehicle_description(self) -> str:
        beat = self.latest["HEARTBEAT"]
        return (f"vehicle {self.target_system}/{self.target_component} "
                f"({enum_name('MAV_AUTOPILOT', beat.autopilot)})")

    def home_position(self) -> GeoPoint | None:
        """The vehicle's home (HOME_POSITION: latitude, longitude, altitude AMSL); None before it arrived or when
        it is not a valid position (a vehicle without a fix may send zeros or out-of-range values)."""
        home = self.latest.get("HOME_POSITION")
        if home is None:
            return None
        if self._home_read[0] is not home:  # read once per message: the runner asks every tick
            try:
                point = GeoPoint(home.latitude / 1e7, home.longitude / 1e7, home.altitude / 1000.0)
            except ValueError:
                point = None
            self._home_read = (home, point)
        return self._home_read[1]

    def home_altitude_amsl(self) -> float | None:
        """Home's altitude above mean sea level (m), from HOME_POSITION; None before it arrived."""
        home = self.home_position()
        return None if home is None else home.alt_m

    def battery_percent(self) -> float | None:
        """Battery remaining (SYS_STATUS), None if unknown."""
        status = self.latest.get("SYS_STATUS")
        return None if status is None or status.battery_remaining < 0 else float(status.battery_remaining)

    def ack_for(self, command: int, since_s: float) -> CommandAck | None:
        """The first ACK of ``command`` received at or after ``since_s``."""
        return first_ack(self.acks, command, since_s)

    # ------------------------------------------------------------------ what the runner sends
    def _target(self) -> tuple[int, int]:
        if self.target_system is None:
            raise LinkError("no vehicle discovered yet (no autopilot HEARTBEAT received)")
        return self.target_system, self.target_component

    def send_command(self, command: int, params: tuple[float, ...], confirmation: int = 0) -> None:
        padded = tuple(params) + (0.0,) * (7 - len(params))
        self._mav.command_long_send(*self._target(), command, confirmation, *padded)

    def request_params(self, names: tuple[str, ...], again: bool = False) -> None:
        """PARAM_REQUEST_READ for each of ``names`` not read yet (``again``: all of them); the answers land in
        :attr:`params`, as do the PARAM_VALUEs the vehicle sends when one of them changes."""
        self._params_wanted.update(names)
        for name in names:
            if again or name not in self.params:
                self._mav.param_request_read_send(*self._target(), name.encode(), -1)

    def _param_number(self, msg) -> float:
        """PARAM_VALUE's number: PX4 puts an integer's bytes in the float field ("bytewise", announced in
        AUTOPILOT_VERSION); ArduPilot sends every value as a float."""
        if self.autopilot == mavlink.MAV_AUTOPILOT_PX4 and msg.param_type in INTEGER_PARAM_TYPES:
            return float(struct.unpack("<i", struct.pack("<f", msg.param_value))[0])
        return float(msg.param_value)

    def request_message_interval(self, message_id: int, rate_hz: float) -> None:
        self.send_command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, (message_id, 1e6 / rate_hz))

    def request_message(self, message_id: int) -> None:
        """MAV_CMD_REQUEST_MESSAGE: send ``message_id`` once (HOME_POSITION, which ArduPilot does not stream)."""
        self.send_command(mavlink.MAV_CMD_REQUEST_MESSAGE, (message_id,))

    def send_timesync_request(self, ts1: int) -> None:
        """TIMESYNC with tc1 = 0: PX4 and ArduPilot answer at once, echoing ``ts1`` (autonomy.uplink_probe)."""
        self._mav.timesync_send(0, ts1)

    def take_timesync_replies(self) -> list[int]:
        replies, self.timesync_replies = self.timesync_replies, []
        return replies

    def send_velocity(self, command: VelocityCommand, now_s: float) -> None:
        del now_s  # the stream's schedule; the message carries our boot time
        self._mav.set_position_target_local_ned_send(
            *setpoint_message_args(command, self.time_boot_ms, *self._target()))

    def close(self) -> None:
        """Close the pymavlink connection."""
        self.conn.close()
