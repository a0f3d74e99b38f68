"""The simulated vehicle: dynamics + sensors + autopilot behind MAVLink endpoints.

One :meth:`SimulatedVehicle.step` is one physics tick: read what the clients sent, let the autopilot
pick a velocity command, advance the dynamics and sensors, then send the telemetry that is due. The
same method runs in lockstep (the caller steps) and in real time (:mod:`sitl_bridge.server` paces it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

from pymavlink.dialects.v20 import common as mavlink

from missions.geodesy import GeoPoint, LocalFrame
from missions.signing import KEY_BYTES, LinkSigning, simulated_timestamp
from sitl_bridge import dynamics, telemetry
from sitl_bridge.autopilot import ACCEPTED, DENIED, Autopilot, AutopilotEvent, as_int
from sitl_bridge.link import Link
from sitl_bridge.params import ParameterStore, decode_bytewise, encode_bytewise
from sitl_bridge.px4_modes import FlightMode
from sitl_bridge.sensors import SensorConfig, SensorSuite
from sitl_bridge.signing import requested_key, vehicle_signing

AUTOPILOT_COMPONENT = mavlink.MAV_COMP_ID_AUTOPILOT1
CAMERA_COMPONENT = mavlink.MAV_COMP_ID_CAMERA  # zoom commands may be addressed to the camera
DEFAULT_HOME = GeoPoint(47.397742, 8.545594, 488.0)  # PX4 SITL's default home (Zurich)


@dataclass(frozen=True)
class VehicleConfig:
    """Everything that defines one simulated vehicle; the same config and seed give the same flight."""

    home: GeoPoint = DEFAULT_HOME
    """Geodetic home: the local NED origin, where the vehicle starts on the ground."""
    physics_rate_hz: float = 100.0
    """Physics ticks per simulated second (>= 100)."""
    seed: int = 0
    """Seeds the sensor noise (the only randomness in the vehicle)."""
    system_id: int = 1
    """MAVLink system id of the vehicle (component id is always 1, the autopilot)."""
    airframe: dynamics.MultirotorParams = field(default_factory=dynamics.MultirotorParams)
    """Physical limits, time constants and battery of the multirotor."""
    wind: dynamics.Wind = field(default_factory=dynamics.Wind)
    """Steady wind and gusts."""
    sensors: SensorConfig = field(default_factory=SensorConfig)
    """GPS, barometer and attitude noise."""
    params: dict[str, float] = field(default_factory=dict)
    """PX4 parameter overrides by name (see sitl_bridge.params.PARAM_SPECS)."""
    telemetry_rates_hz: dict[int, float] = field(default_factory=dict)
    """Overrides of the default stream rates by message id (0 disables a stream)."""
    signing_key: bytes | None = field(default=None, repr=False)
    """MAVLink 2 signing secret (32 bytes, see missions.signing.load_key_file); None: no signing."""

    def __post_init__(self) -> None:
        if not 100.0 <= self.physics_rate_hz <= 2000.0:
            raise ValueError(f"physics_rate_hz must be in [100, 2000], got {self.physics_rate_hz}")
        if not 1 <= self.system_id <= 250:
            raise ValueError(f"system_id must be in [1, 250], got {self.system_id}")
        if self.signing_key is not None and len(self.signing_key) != KEY_BYTES:
            raise ValueError(f"signing_key must be {KEY_BYTES} bytes, got {len(self.signing_key)}; "
                             "load it with missions.signing.load_key_file")


class _LinkWriter:
    """The ``file`` pymavlink's encoder writes to: forwards each packed message to the link."""

    def __init__(self, link: Link):
        self.write = link.send


class Endpoint:
    """One link with its own MAVLink encoder/decoder (sequence numbers) and telemetry schedule."""

    def __init__(self, link: Link, system_id: int, rates_hz: dict[int, float]):
        self.link = link
        self.mav = mavlink.MAVLink(_LinkWriter(link), srcSystem=system_id, srcComponent=AUTOPILOT_COMPONENT)
        self.mav.robust_parsing = True  # malformed bytes become BAD_DATA messages, not exceptions
        self.schedule = telemetry.TelemetrySchedule(rates_hz)
        self.bad_frames = 0

    def send(self, msg: mavlink.MAVLink_message) -> None:
        self.mav.send(msg)

    def parse(self, data: bytes) -> list[mavlink.MAVLink_message]:
        """The messages in one received datagram. Links carry whole frames per datagram (UDP, the memory link),
        so bytes left over are a damaged frame: dropped and counted, never allowed to swallow the next datagram
        (a garbage header claiming 255 bytes would otherwise eat the following valid command)."""
        messages = self.mav.parse_buffer(data) or []
        if self.mav.buf_len():
            self.bad_frames += 1
            self.mav.buf, self.mav.buf_index = bytearray(), 0
            self.mav.expected_length = mavlink.HEADER_LEN_V1 + 2
        return messages


class SimulatedVehicle:
    """A PX4-like multirotor; call :meth:`step` once per physics tick."""

    def __init__(self, config: VehicleConfig | None = None, links: list[Link] | tuple[Link, ...] = (),
                 on_event: Callable[[AutopilotEvent], None] | None = None,
                 signing_timestamp: Callable[[], int] | None = None):
        """``signing_timestamp``: the signing clock (default: simulated time from the MAVLink epoch, for
        deterministic lockstep runs; real-time servers pass missions.signing.wall_timestamp)."""
        self.config = config = config or VehicleConfig()
        self.dt_s = 1.0 / config.physics_rate_hz
        self.tick = 0
        self.frame = LocalFrame(config.home)
        self.state = dynamics.VehicleState(battery_wh=config.airframe.battery_capacity_wh)
        self.command = dynamics.HOVER
        self.ground_velocity = (0.0, 0.0, 0.0)
        self.yaw_rate_rad_s = 0.0
        self.power_w = 0.0
        self.sensors = SensorSuite(config.sensors, seed=config.seed)
        self.params = ParameterStore(config.params)
        self.autopilot = Autopilot(self.params, config.airframe, home_alt_m=config.home.alt_m)
        rates = {**telemetry.DEFAULT_RATES_HZ, **config.telemetry_rates_hz}
        self.endpoints = [Endpoint(link, config.system_id, rates) for link in links]
        self.on_event = on_event
        self.unhandled: dict[str, int] = {}
        self.handler_errors = 0
        self.signing_timestamp = signing_timestamp or simulated_timestamp(lambda: self.time_s)
        self.signing: LinkSigning | None = None
        self.setup_signing_refused = 0
        if config.signing_key is not None:
            self._enable_signing(config.signing_key)
        self._handlers = {
            "COMMAND_LONG": self._on_command_long,
            "COMMAND_INT": self._on_command_int,
            "SET_POSITION_TARGET_LOCAL_NED": self._on_setpoint,
            "PARAM_REQUEST_LIST": self._on_param_request_list,
            "PARAM_REQUEST_READ": self._on_param_request_read,
            "PARAM_SET": self._on_param_set,
            "TIMESYNC": self._on_timesync,
            "SET_MODE": self._on_set_mode,
            "MISSION_REQUEST_LIST": self._on_mission_request_list,
            "HEARTBEAT": lambda endpoint, msg: None,
            "SETUP_SIGNING": self._on_setup_signing,
        }
        self.sensors.update(0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        self.autopilot.gps_ok = self.sensors.gps is not None

    # ------------------------------------------------------------------ time
    @property
    def time_s(self) -> float:
        """Simulated seconds since boot (exact multiple of the tick)."""
        return self.tick * self.dt_s

    @property
    def time_boot_ms(self) -> int:
        return int(self.tick * 1000 // self.config.physics_rate_hz)

    def run(self, seconds: float) -> None:
        """Lockstep convenience: step for ``seconds`` of simulated time."""
        for _ in range(int(round(seconds / self.dt_s))):
            self.step()

    # ------------------------------------------------------------------ one tick
    def step(self) -> None:
        """Advance one physics tick: receive, decide, move, sense, send."""
        now = self.time_s
        for endpoint in self.endpoints:
            for data in endpoint.link.receive():
                self.receive(endpoint, data)
        ap = self.autopilot
        self.command = ap.guidance(now, self.state)
        airframe, wind = self.config.airframe, self.config.wind
        previous_yaw = self.state.yaw_rad
        self.power_w = dynamics.power_w(self.state, self.command, airframe, wind, ap.armed)
        self.state = state = dynamics.step(self.state, self.command, airframe, wind, self.dt_s, armed=ap.armed)
        self.tick += 1
        self.yaw_rate_rad_s = math.remainder(state.yaw_rad - previous_yaw, math.tau) / self.dt_s
        self.ground_velocity = dynamics.ground_velocity(state, airframe, wind)
        self.sensors.update(self.time_s, (state.north_m, state.east_m, state.down_m), self.ground_velocity,
                            dynamics.attitude(state, airframe, wind))
        ap.gps_ok = self.sensors.gps is not None
        self._flush_events()
        self._send_telemetry()

    def _flush_events(self) -> None:
        ap = self.autopilot
        if ap.state_changed:  # MAVSDK learns modes only from heartbeats: announce changes at once
            ap.state_changed = False
            self.broadcast(telemetry.heartbeat(self))
        for event in ap.events:
            self.broadcast(mavlink.MAVLink_statustext_message(event.severity, event.text.encode()[:50], 0, 0))
            if self.on_event:
                self.on_event(event)
        ap.events.clear()

    def _send_telemetry(self) -> None:
        now = self.time_s
        built: dict[int, mavlink.MAVLink_message | None] = {}
        for endpoint in self.endpoints:
            for msg_id in endpoint.schedule.due(now):
                if msg_id not in built:
                    built[msg_id] = telemetry.BUILDERS[msg_id](self)
                if built[msg_id] is not None:
                    endpoint.send(built[msg_id])

    def broadcast(self, msg: mavlink.MAVLink_message) -> None:
        """Send one message on every link."""
        for endpoint in self.endpoints:
            endpoint.send(msg)

    def log(self, text: str) -> None:
        """Record an event that is not the autopilot's own (commands, parameters) for the operator log."""
        if self.on_event:
            self.on_event(AutopilotEvent(self.time_s, text, mavlink.MAV_SEVERITY_DEBUG))

    # ------------------------------------------------------------------ incoming messages
    def receive(self, endpoint: Endpoint, data: bytes) -> None:
        """Parse bytes that arrived on ``endpoint`` and act on every admitted message (any bytes are safe)."""
        now = self.time_s
        for msg in endpoint.parse(data):
            if self._admitted(msg):
                self._handle(endpoint, msg, now)

    def _handle(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        name = msg.get_type()
        handler = self._handlers.get(name)
        if handler is not None:
            try:
                handler(endpoint, msg)
            except Exception as exc:  # a bad message must never take the vehicle down
                self.handler_errors += 1
                self.log(f"error handling {name}: {exc!r}")
        elif name == "BAD_DATA":
            endpoint.bad_frames += 1
        else:  # ids this dialect does not know share one counter: garbage can make 16 million of them
            name = "UNKNOWN" if msg.get_msgId() == mavlink.MAVLINK_MSG_ID_UNKNOWN else name
            self.unhandled[name] = self.unhandled.get(name, 0) + 1

    def _admitted(self, msg: mavlink.MAVLink_message) -> bool:
        """With signing on, whether the frame is signed with our key and fresh (or on PX4's unsigned allow-list)."""
        if self.signing is None or msg.get_type() == "BAD_DATA":
            return True
        accepted, verdict = self.signing.admit(msg.get_msgbuf(), msg.get_msgId(), msg.get_type())
        if not accepted and self.signing.rejected[verdict] == 1:  # log each reason once; the rest are counted
            self.log(f"signing: rejected {msg.get_type()} from {msg.get_srcSystem()}/{msg.get_srcComponent()} "
                     f"({verdict}); further rejections are only counted")
        return accepted

    def _for_us(self, msg: mavlink.MAVLink_message, components: tuple[int, ...] = (AUTOPILOT_COMPONENT,)) -> bool:
        return (msg.target_system in (0, self.config.system_id)
                and msg.target_component in (0, *components))

    def _on_command_long(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7)
        self._execute(endpoint, msg, msg.command, params)

    def _on_command_int(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        params = (msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x), float(msg.y), msg.z)
        self._execute(endpoint, msg, msg.command, params)

    def _execute(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, command: int, p: tuple[float, ...]) -> None:
        if not self._for_us(msg, (AUTOPILOT_COMPONENT, CAMERA_COMPONENT)):
            return
        now = self.time_s
        follow_up: mavlink.MAVLink_message | None = None
        if command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            result = self._set_message_interval(endpoint, as_int(p[0]), p[1], now)
        elif command in (mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES):
            msg_id = as_int(p[0]) if command == mavlink.MAV_CMD_REQUEST_MESSAGE else mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION
            builder = telemetry.BUILDERS.get(msg_id)
            follow_up = builder(self) if builder else None
            result = ACCEPTED if follow_up is not None else DENIED
        else:
            result = self.autopilot.handle_command(command, p, now, self.state)
        endpoint.send(mavlink.MAVLink_command_ack_message(command, result, 0, 0, msg.get_srcSystem(),
                                                          msg.get_srcComponent()))
        if follow_up is not None:  # the spec: ACK first, then the requested message
            endpoint.send(follow_up)
        if command not in (mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL) or result != ACCEPTED:
            self.log(f"command {_command_name(command)} from {msg.get_srcSystem()}/{msg.get_srcComponent()}: "
                     f"{_result_name(result)}")

    def _set_message_interval(self, endpoint: Endpoint, msg_id: int, interval_us: float, now: float) -> int:
        if msg_id not in telemetry.BUILDERS or msg_id == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            return DENIED
        if not math.isfinite(interval_us):
            return DENIED
        if interval_us == 0:  # back to the default rate
            rate = {**telemetry.DEFAULT_RATES_HZ, **self.config.telemetry_rates_hz}.get(msg_id, 0.0)
            endpoint.schedule.set_interval(msg_id, 1.0 / rate if rate > 0 else None, now)
        elif interval_us < 0:
            endpoint.schedule.set_interval(msg_id, None, now)
        else:
            endpoint.schedule.set_interval(msg_id, max(interval_us * 1e-6, self.dt_s), now)
        return ACCEPTED

    def _on_setpoint(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        if not self._for_us(msg):
            return
        self.autopilot.handle_setpoint(self.time_s, self.state, msg.coordinate_frame, msg.type_mask,
                                       (msg.x, msg.y, msg.z), (msg.vx, msg.vy, msg.vz), msg.yaw, msg.yaw_rate)

    def _on_set_mode(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        # The legacy SET_MODE message: no ACK in the protocol.
        if msg.target_system != self.config.system_id:
            return
        mode = FlightMode.from_custom_mode(msg.custom_mode)
        if mode is not None and msg.base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            self.autopilot.set_mode(mode, self.time_s, self.state, "SET_MODE")

    # ------------------------------------------------------------------ parameters
    def _param_value(self, name: str) -> mavlink.MAVLink_message:
        spec = self.params.specs[name]
        return mavlink.MAVLink_param_value_message(name.encode(), encode_bytewise(self.params[name], spec.kind),
                                                   spec.kind, len(self.params), self.params.index(name))

    def _on_param_request_list(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        if self._for_us(msg):
            for name in self.params.names:
                endpoint.send(self._param_value(name))

    def _on_param_request_read(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        if not self._for_us(msg):
            return
        if msg.param_index >= 0:
            if msg.param_index < len(self.params):
                endpoint.send(self._param_value(self.params.names[msg.param_index]))
        elif _param_name(msg.param_id) in self.params.specs:
            endpoint.send(self._param_value(_param_name(msg.param_id)))

    def _on_param_set(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        if not self._for_us(msg):
            return
        name = _param_name(msg.param_id)
        spec = self.params.specs.get(name)
        if spec is None:
            self.log(f"PARAM_SET {name!r}: unknown parameter, ignored")
            return
        error = self.params.set(name, decode_bytewise(msg.param_value, spec.kind))
        self.log(f"PARAM_SET {name} = {self.params[name]:g}" + (f" refused: {error}" if error else ""))
        # Echo the (possibly unchanged) value on every link, as PX4 does, so all clients stay in sync.
        self.broadcast(self._param_value(name))

    # ------------------------------------------------------------------ small protocol services
    def _on_timesync(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        if msg.tc1 == 0:  # a request: answer with our time in ns
            endpoint.send(mavlink.MAVLink_timesync_message(int(self.time_s * 1e9), msg.ts1))

    # ------------------------------------------------------------------ signing
    def _enable_signing(self, key: bytes) -> None:
        self.signing = vehicle_signing(key, self.signing_timestamp)
        for link_id, endpoint in enumerate(self.endpoints):
            self.signing.install(endpoint.mav, link_id)

    def _on_setup_signing(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        # No ACK in the protocol: the sender learns the outcome from whether our next frames verify.
        if not self._for_us(msg):
            return
        if self.autopilot.armed:  # a key change in flight could cut the link to the pilot
            self.setup_signing_refused += 1
            self.log("SETUP_SIGNING refused: the vehicle is armed")
            return
        key = requested_key(msg)
        if key is None:
            self.signing = None
            for other in self.endpoints:
                other.mav.signing = mavlink.MAVLinkSigning()
            self.log("SETUP_SIGNING: signing switched off (all-zero key)")
        elif self.signing is None:
            self._enable_signing(key)
            self.log("SETUP_SIGNING: signing switched on with the new key")
        else:
            self.signing.replace_key(key, msg.initial_timestamp)
            self.log("SETUP_SIGNING: new key installed")

    def _on_mission_request_list(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        if self._for_us(msg):  # no missions are stored; saying so stops ground stations waiting
            endpoint.send(mavlink.MAVLink_mission_count_message(msg.get_srcSystem(), msg.get_srcComponent(), 0,
                                                                msg.mission_type))


def _param_name(raw: str | bytes) -> str:
    if isinstance(raw, bytes):
        raw = raw.decode("ascii", errors="replace")
    return raw.split("\x00", 1)[0]


def _command_name(command: int) -> str:
    entry = mavlink.enums["MAV_CMD"].get(command)
    return entry.name.removeprefix("MAV_CMD_") if entry else str(command)


def _result_name(result: int) -> str:
    return mavlink.enums["MAV_RESULT"][result].name.removeprefix("MAV_RESULT_")
