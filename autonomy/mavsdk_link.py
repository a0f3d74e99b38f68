"""The runner's optional MAVSDK backend (``hrlsac mission run --backend mavsdk``).

:class:`MavsdkLink` is the runner's :class:`autonomy.vehicle_connection.VehicleConnection` backed by MAVSDK-Python's
asyncio API instead of raw pymavlink: arming, take-off, OFFBOARD and RTL go through MAVSDK's
Action and Offboard plugins (setpoints through ``Offboard.set_velocity_ned``), telemetry comes from its
Telemetry subscriptions and is handed to the runner as GLOBAL_POSITION_INT messages (built with pymavlink), so
the Kalman filter and everything after it are the same code.

MAVSDK runs in its own thread with its own event loop; each call becomes a future, and its outcome a COMMAND_ACK
in the runner's terms (ACCEPTED, or FAILED with MAVSDK's error). Every call is bounded by the runner's command
timeout; MAVSDK cannot cancel a call already running in its executor, so at the end MAVSDK is only destroyed once
no call is pending (otherwise the daemon thread is left to the process exit). No tlog: MAVSDK does not expose the
bytes it exchanges. The uplink probe's TIMESYNC requests (autonomy.uplink_probe) go out and their replies come
back through MAVSDK's MavlinkDirect plugin, the one way MAVSDK sends and reads a message it has no plugin for.
"""
from __future__ import annotations

import asyncio
import json
import threading
from collections import deque
from concurrent.futures import Future
from typing import Callable

from pymavlink.dialects.v20 import common as mavlink

from autonomy.setpoints import VelocityCommand
from autonomy.vehicle_connection import MAX_STATUS_TEXTS, CommandAck, first_ack, texts_after
from autonomy.vehicle_link import LinkError
from mavlink_signing import LinkSigning
from missions.geodesy import GeoPoint

_FLIGHT_MODES = {"HOLD": "LOITER", "RETURN_TO_LAUNCH": "RTL", "TAKEOFF": "TAKEOFF", "LAND": "LAND",
                 "OFFBOARD": "OFFBOARD", "MISSION": "MISSION", "POSCTL": "POSCTL", "ALTCTL": "ALTCTL",
                 "MANUAL": "MANUAL"}


def mavsdk_url(url: str) -> str:
    """Our connection URL in MAVSDK's spelling (udpin:HOST:PORT -> udpin://HOST:PORT, ...)."""
    for ours, theirs in (("udpin:", "udpin://"), ("udpout:", "udpout://"), ("tcp:", "tcpout://"),
                         ("serial:", "serial://")):
        if url.startswith(ours) and not url.startswith(theirs):
            return theirs + url[len(ours):]
    raise LinkError(f"cannot use connection {url!r} with MAVSDK: write udpin:HOST:PORT, udpout:HOST:PORT, "
                    "tcp:HOST:PORT or serial:DEVICE[:BAUD]")


class MavsdkLink:
    """See the module docstring; ``clock()`` is the run's (wall) time in seconds."""

    def __init__(self, url: str, clock: Callable[[], float], connect_timeout_s: float = 15.0):
        from mavsdk.asyncio import ComponentType, Configuration, Mavsdk

        self.clock = clock
        self.recorder = None
        self.signing: LinkSigning | None = None  # MAVSDK's Python API cannot sign
        self.target_system: int | None = None
        self.target_component = 1
        self.last_vehicle_message_s: float | None = None
        self.acks: deque = deque(maxlen=64)
        self.status_texts: list[str] = []
        self.status_log: deque = deque(maxlen=MAX_STATUS_TEXTS)
        self.status_count = 0
        self.sent_heartbeats = 0  # MAVSDK sends the companion heartbeat itself
        self._mode: str | None = None
        self._armed = False
        self._home: GeoPoint | None = None
        self._battery: float | None = None
        self._samples: list = []
        self.params: dict[str, float] = {}  # read with request_params (MAVSDK's Param plugin decodes them)
        self._timesync_replies: deque[int] = deque(maxlen=1000)  # ts1 of TIMESYNC replies (MAVSDK's thread appends)
        self._pending: set[Future] = set()
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="mavsdk", daemon=True)
        self._thread.start()
        configuration = Configuration.create_with_component_type(ComponentType.COMPANION_COMPUTER)
        self.companion_system_id: int = configuration.system_id  # MAVSDK's own (1 for a companion computer)
        self._drone = Mavsdk(configuration)
        self._system = self._call(self._connect(mavsdk_url(url), connect_timeout_s)).result(connect_timeout_s + 5)

    # ------------------------------------------------------------------ the MAVSDK thread
    def _call(self, coroutine) -> Future:
        future = asyncio.run_coroutine_threadsafe(coroutine, self._loop)
        self._pending.add(future)
        future.add_done_callback(self._pending.discard)
        return future

    async def _connect(self, url: str, timeout_s: float):
        from mavsdk.asyncio.plugins.action import ActionAsync
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
        from mavsdk.asyncio.plugins.offboard import OffboardAsync
        from mavsdk.asyncio.plugins.param import ParamAsync
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        await self._drone.add_any_connection(url)
        system = await self._drone.first_autopilot(timeout_s=timeout_s)
        if system is None:
            raise LinkError(f"MAVSDK saw no autopilot on {url} within {timeout_s:g} s")
        self.action, self.offboard, self.telemetry = ActionAsync(system), OffboardAsync(system), TelemetryAsync(system)
        self.param, self.direct = ParamAsync(system), MavlinkDirectAsync(system)
        for watch in (self._watch_position, self._watch_mode, self._watch_armed, self._watch_home,
                      self._watch_battery, self._watch_status_text, self._watch_timesync):
            self._loop.create_task(watch())
        self.target_system = 1
        return system

    async def _watch_position(self) -> None:
        velocity = (0.0, 0.0, 0.0)

        async def velocities():
            nonlocal velocity
            async for v in self.telemetry.subscribe_velocity_ned():
                velocity = (v.north_m_s, v.east_m_s, v.down_m_s)

        self._loop.create_task(velocities())
        async for p in self.telemetry.subscribe_position():
            now = self.clock()
            self.last_vehicle_message_s = now
            vn, ve, vd = velocity
            self._samples.append(mavlink.MAVLink_global_position_int_message(
                int(round(now * 1000)) & 0xFFFFFFFF, int(round(p.latitude_deg * 1e7)),
                int(round(p.longitude_deg * 1e7)), int(round(p.absolute_altitude_m * 1000)),
                int(round(p.relative_altitude_m * 1000)), int(round(vn * 100)), int(round(ve * 100)),
                int(round(vd * 100)), 65535))

    async def _watch_mode(self) -> None:
        async for mode in self.telemetry.subscribe_flight_mode():
            self._mode = _FLIGHT_MODES.get(mode.name, mode.name)

    async def _watch_armed(self) -> None:
        async for armed in self.telemetry.subscribe_armed():
            self._armed = bool(armed)

    async def _watch_home(self) -> None:
        async for home in self.telemetry.subscribe_home():
            try:
                self._home = GeoPoint(float(home.latitude_deg), float(home.longitude_deg),
                                      float(home.absolute_altitude_m))
            except ValueError:  # NaN before the vehicle has a home
                self._home = None

    async def _watch_battery(self) -> None:
        async for battery in self.telemetry.subscribe_battery():
            self._battery = float(battery.remaining_percent)

    async def _watch_status_text(self) -> None:
        """The autopilot's STATUSTEXTs (MAVSDK joins chunked ones): the runner's safety vetoes read them."""
        async for status in self.telemetry.subscribe_status_text():
            self.status_texts = [*self.status_texts[1 - MAX_STATUS_TEXTS:], status.text]  # quoted in refusals
            self.status_log.append((self.clock(), status.text))
            self.status_count += 1  # after the append: the runner's thread reads the log by this count

    async def _watch_timesync(self) -> None:
        """TIMESYNC replies (tc1 != 0; tc1 = 0 is a request), as JSON from MavlinkDirect: their ts1 for the probe."""
        async for message in self.direct.subscribe_message("TIMESYNC"):
            try:
                fields = json.loads(message.fields_json)
                if int(fields["tc1"]) != 0:
                    self._timesync_replies.append(int(fields["ts1"]))
            except (ValueError, KeyError, TypeError):  # a malformed message is not an answer
                continue

    # ------------------------------------------------------------------ the VehicleConnection interface
    def tick(self) -> list:
        samples, self._samples = self._samples, []
        return samples

    @property
    def discovered(self) -> bool:
        return self.target_system is not None

    @property
    def flight_mode(self) -> str | None:
        return self._mode

    @property
    def armed(self) -> bool:
        return self._armed

    @property
    def autopilot(self) -> int:
        """MAVSDK names modes and runs take-off and offboard itself, PX4-style, whatever the autopilot."""
        return mavlink.MAV_AUTOPILOT_PX4

    def status_since(self, count: int) -> list[tuple[float, str]]:
        return texts_after(self.status_log, self.status_count, count)

    def vehicle_description(self) -> str:
        return "autopilot found by MAVSDK"

    def home_position(self) -> GeoPoint | None:
        return self._home

    def home_altitude_amsl(self) -> float | None:
        return None if self._home is None else self._home.alt_m

    def battery_percent(self) -> float | None:
        return self._battery

    def ack_for(self, command: int, since_s: float) -> CommandAck | None:
        return first_ack(self.acks, command, since_s)

    def request_message_interval(self, message_id: int, rate_hz: float) -> None:
        """MAVSDK sets rates per telemetry topic, not per message: only the position rate is set (MAVSDK asks for
        the home position and battery itself)."""
        if message_id == mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
            self._call(self.telemetry.set_rate_position(rate_hz))

    def request_message(self, message_id: int) -> None:
        """MAVSDK requests what its subscriptions need (the home position among them) itself."""

    def request_params(self, names: tuple[str, ...], again: bool = False) -> None:
        """Each of ``names`` not read yet (``again``: all of them), through MAVSDK's Param plugin (which knows each
        autopilot's encoding); the answers land in :attr:`params`."""
        for name in names:
            if again or name not in self.params:
                self._call(self._read_param(name))

    async def _read_param(self, name: str) -> None:
        try:  # the plugin asks for one type; a parameter of the other answers WRONG_TYPE
            self.params[name] = float(await self.param.get_param_float(name))
        except Exception:  # noqa: BLE001 - MAVSDK raises ParamError; anything else leaves the name unread too
            self.params[name] = float(await self.param.get_param_int(name))

    def send_command(self, command: int, params: tuple[float, ...], confirmation: int = 0) -> None:
        """The runner's COMMAND_LONGs, as MAVSDK calls; the outcome arrives as a CommandAck."""
        if command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            call = self.action.arm() if params[0] else self.action.disarm()
        elif command == mavlink.MAV_CMD_NAV_TAKEOFF:
            call = self._takeoff(params[6] - (self.home_altitude_amsl() or 0.0))
        elif command == mavlink.MAV_CMD_DO_SET_MODE:
            call = self.offboard.start()
        elif command == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            call = self.action.return_to_launch()
        else:  # camera zoom and the like: not offered by this backend
            self.acks.append(CommandAck(command, mavlink.MAV_RESULT_UNSUPPORTED, self.clock()))
            return
        self._call(call).add_done_callback(lambda future: self._acknowledge(command, future))

    async def _takeoff(self, relative_altitude_m: float) -> None:
        await self.action.set_takeoff_altitude(relative_altitude_m)
        await self.action.takeoff()

    def _acknowledge(self, command: int, future: Future) -> None:
        error = future.exception()
        if error is not None:
            self.status_texts.append(str(error).splitlines()[0] if str(error) else type(error).__name__)
        result = mavlink.MAV_RESULT_ACCEPTED if error is None else mavlink.MAV_RESULT_FAILED
        self.acks.append(CommandAck(command, result, self.clock()))

    def send_timesync_request(self, ts1: int) -> None:
        """TIMESYNC with tc1 = 0 through MavlinkDirect (the vehicle echoes ``ts1``: autonomy.uplink_probe)."""
        from mavsdk.plugins.mavlink_direct.mavlink_direct import MavlinkMessage

        fields = {"tc1": 0, "ts1": int(ts1), "target_system": self.target_system or 0, "target_component": 0}
        self._call(self.direct.send_message(MavlinkMessage(
            message_name="TIMESYNC", target_system_id=self.target_system or 0, fields_json=json.dumps(fields))))

    def take_timesync_replies(self) -> list[int]:
        replies = []
        while self._timesync_replies:  # popleft is atomic against MAVSDK's thread appending
            replies.append(self._timesync_replies.popleft())
        return replies

    def send_velocity(self, command: VelocityCommand, now_s: float) -> None:
        from mavsdk.asyncio.plugins.offboard import VelocityNedYaw

        self._call(self.offboard.set_velocity_ned(VelocityNedYaw(command.vn, command.ve, command.vd, 0.0)))

    def close(self, timeout_s: float = 5.0) -> None:
        """Destroy MAVSDK once no call is pending (see the module docstring), then stop its loop."""
        for future in list(self._pending):
            try:
                future.result(timeout_s)
            except Exception:  # noqa: BLE001 - we are closing; the outcome no longer matters
                pass
        try:
            asyncio.run_coroutine_threadsafe(self._stop_watching(), self._loop).result(timeout_s)
        except Exception:  # noqa: BLE001 - a subscription that does not stop must not block the exit
            pass
        if not self._pending:
            self._loop.call_soon_threadsafe(self._drone.destroy)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout_s)

    @staticmethod
    async def _stop_watching() -> None:
        """Cancel the telemetry subscriptions and wait for them to end."""
        tasks = [task for task in asyncio.all_tasks() if task is not asyncio.current_task()]
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
