"""What the mission runner needs from its connection to the vehicle, whichever MAVLink client provides it.

Two clients implement :class:`VehicleConnection`: :class:`autonomy.vehicle_link.VehicleLink` (pymavlink, raw
MAVLink, records a tlog, signs) and :class:`autonomy.mavsdk_link.MavsdkLink` (MAVSDK's plugins). The runner, its
failsafes and its receive path are typed with the protocol and never ask which client they have. What one client
cannot do, the protocol says how it reports: no signing is ``signing`` None; a command the client cannot send is
answered with an UNSUPPORTED :class:`CommandAck`; a message it cannot request is a request that does nothing (the
client asks for it itself).

The pieces both clients share (the acknowledgement record, the STATUSTEXT log) live here too.
"""
from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:  # types only: the protocol loads neither client
    from autonomy.setpoints import VelocityCommand
    from mavlink_signing import LinkSigning
    from missions.geodesy import GeoPoint

MAX_STATUS_TEXTS = 100  # the runner quotes the last two; a chatty or hostile vehicle must not grow memory


@dataclass
class CommandAck:
    """A COMMAND_ACK (or a client's outcome of a command, in the same terms) and when it arrived."""

    command: int
    result: int
    time_s: float


def first_ack(acks: Iterable[CommandAck], command: int, since_s: float) -> CommandAck | None:
    """The first acknowledgement of ``command`` received at or after ``since_s``."""
    return next((a for a in acks if a.command == command and a.time_s >= since_s), None)


def texts_after(log: deque, total: int, count: int) -> list[tuple[float, str]]:
    """The (time, text) STATUSTEXTs of ``log`` received after the first ``count`` of ``total`` ever received (at
    most the last MAX_STATUS_TEXTS, which the log keeps)."""
    entries = list(log)
    new = min(total - count, len(entries))
    return entries[len(entries) - new:] if new > 0 else []


class VehicleConnection(Protocol):
    """The runner's side of the link to one vehicle. It never waits: the runner owns time and calls :meth:`tick`."""

    @property
    def clock(self) -> Callable[[], float]:
        """The run's clock (seconds): simulated in lockstep, the wall clock otherwise."""

    # ------------------------------------------------------------------ what the vehicle said
    def tick(self) -> list:
        """Receive everything waiting (and send the companion heartbeat when due); the messages received, telemetry
        positions as GLOBAL_POSITION_INT (``autonomy.vehicle_time.receive_telemetry`` fuses them)."""

    @property
    def discovered(self) -> bool:
        """Whether the vehicle has been found (its first autopilot HEARTBEAT)."""

    @property
    def autopilot(self) -> int | None:
        """The vehicle's MAV_AUTOPILOT, None before discovery."""

    @property
    def flight_mode(self) -> str | None:
        """The mode as pymavlink spells it for the autopilot ("OFFBOARD", "GUIDED", "RTL", ...), None before one."""

    @property
    def armed(self) -> bool:
        """Whether the vehicle says it is armed."""

    @property
    def last_vehicle_message_s(self) -> float | None:
        """When the vehicle was last heard (run's clock), None before."""

    @property
    def status_texts(self) -> list[str]:
        """The latest STATUSTEXTs (at most MAX_STATUS_TEXTS), oldest first: refusals quote the last ones."""

    @property
    def status_count(self) -> int:
        """STATUSTEXTs ever received; :meth:`status_since` reads the log by this count."""

    def status_since(self, count: int) -> list[tuple[float, str]]:
        """The (receive time, text) STATUSTEXTs received after the first ``count``."""

    @property
    def params(self) -> dict[str, float]:
        """The parameters read with :meth:`request_params`, by name."""

    def vehicle_description(self) -> str:
        """One line naming the vehicle found, for the log."""

    def home_position(self) -> GeoPoint | None:
        """The vehicle's home (latitude, longitude, altitude AMSL), None before it is known."""

    def home_altitude_amsl(self) -> float | None:
        """Home's altitude above mean sea level (m), None before it is known."""

    def battery_percent(self) -> float | None:
        """Battery remaining (%), None if unknown."""

    def ack_for(self, command: int, since_s: float) -> CommandAck | None:
        """The first acknowledgement of ``command`` received at or after ``since_s``."""

    def take_timesync_replies(self) -> list[int]:
        """ts1 of the TIMESYNC replies received since the last call (``autonomy.uplink_probe``)."""

    # ------------------------------------------------------------------ what the runner sends
    def send_command(self, command: int, params: tuple[float, ...], confirmation: int = 0) -> None:
        """A COMMAND_LONG (or the client's call for it); the outcome arrives as a :class:`CommandAck`, UNSUPPORTED
        for a command the client cannot send."""

    def request_message_interval(self, message_id: int, rate_hz: float) -> None:
        """Ask the vehicle to stream ``message_id`` at ``rate_hz``."""

    def request_message(self, message_id: int) -> None:
        """Ask the vehicle for ``message_id`` once (nothing to do for a client that asks for it itself)."""

    def request_params(self, names: tuple[str, ...], again: bool = False) -> None:
        """Read each of ``names`` not read yet (``again``: all of them) into :attr:`params`."""

    def send_timesync_request(self, ts1: int) -> None:
        """A TIMESYNC request (tc1 = 0): the vehicle echoes ``ts1`` at once, which tells the runner it hears us."""

    def send_velocity(self, command: VelocityCommand, now_s: float) -> None:
        """One velocity setpoint (``autonomy.setpoints``)."""

    def close(self) -> None:
        """Close the connection at the end of the run."""

    # ------------------------------------------------------------------ about this computer
    @property
    def companion_system_id(self) -> int | None:
        """This computer's MAVLink system id (None: unknown)."""

    @property
    def sent_heartbeats(self) -> int:
        """Companion HEARTBEATs sent by this client (0 when the client's library sends them itself)."""

    @property
    def signing(self) -> LinkSigning | None:
        """The link's MAVLink 2 signing, None when unsigned (or the client cannot sign)."""
