"""The simulated vehicle: dynamics + sensors + an autopilot personality behind MAVLink endpoints.

One :meth:`SimulatedVehicle.step` is one physics tick: read what the clients sent, let the autopilot
pick a velocity command, advance the dynamics and sensors, then send the telemetry that is due. The
same method runs in lockstep (the caller steps) and in real time (:mod:`sitl_bridge.server` paces it).

The autopilot is PX4 (:class:`sitl_bridge.px4.autopilot.Px4Autopilot`) or ArduPilot Copter
(:class:`sitl_bridge.ardupilot.autopilot.ArduCopter`), chosen by ``VehicleConfig.autopilot``; both share everything
else.
Realism options: the autopilot may have booted long before the simulation starts (``boot_time_s``) and may reboot
mid-flight (``reboot_at_s``): the links go silent, the motors stop (an airborne vehicle falls), and the autopilot
comes back disarmed in its boot mode with ``time_boot_ms`` restarting and home and the local origin re-set where
the vehicle then is.
"""
from __future__ import annotations

import math
from typing import Callable

from pymavlink.dialects.v20 import common as mavlink

from mavlink_signing import LinkSigning, simulated_timestamp
from missions.geodesy import GeoPoint, LocalFrame
from sitl_bridge import dynamics, telemetry
from sitl_bridge.ardupilot.autopilot import ArduCopter
from sitl_bridge.ardupilot.fence_protocol import CopterFenceTransfer
from sitl_bridge.ardupilot.item_protocol import CopterTransfers
from sitl_bridge.ardupilot.mission_protocol import CopterMissionTransfer
from sitl_bridge.ardupilot.params import ARDUPILOT_PARAM_SPECS
from sitl_bridge.ardupilot.rally import CopterRallyTransfer
from sitl_bridge.autopilot_base import AutopilotBase, AutopilotEvent
from sitl_bridge.endpoint import Endpoint
from sitl_bridge.link import Link
from sitl_bridge.params import ParameterStore
from sitl_bridge.px4.autopilot import Px4Autopilot
from sitl_bridge.px4.mission_protocol import MissionTransfer
from sitl_bridge.sensors import SensorSuite
from sitl_bridge.signing import vehicle_signing
from sitl_bridge.telemetry_profiles import link_rates_hz, resolve_profile
from sitl_bridge.vehicle_config import VehicleConfig
from sitl_bridge.vehicle_messages import MessageHandlers

STATUSTEXT_LEN = 50  # bytes of STATUSTEXT.text


def make_autopilot(config: VehicleConfig, params: ParameterStore, frame: LocalFrame) -> AutopilotBase:
    """A freshly booted autopilot of the configured personality, in the simulator's NED ``frame``."""
    if config.autopilot == "ardupilot":
        return ArduCopter(params, config.airframe, frame)
    return Px4Autopilot(params, config.airframe, frame)


SYSTEM_ID_PARAM = {"px4": "MAV_SYS_ID", "ardupilot": "SYSID_THISMAV"}
"""The parameter that holds the vehicle's MAVLink system id, read once at boot (PX4's mavlink_main.cpp keeps the id
it started with, "we don't allow them to change during operation"; ArduPilot's GCS::init sets it at boot)."""


def make_params(config: VehicleConfig) -> ParameterStore:
    """The personality's parameter table with the configured overrides (kept across reboots, like flash); the
    configured system id is the default of the system-id parameter, which an override wins over."""
    defaults = {SYSTEM_ID_PARAM[config.autopilot]: config.system_id, **config.params}
    if config.autopilot == "ardupilot":
        return ParameterStore(defaults, ARDUPILOT_PARAM_SPECS)
    return ParameterStore(defaults)


class SimulatedVehicle(MessageHandlers):
    """A multirotor with a PX4 or ArduPilot autopilot; call :meth:`step` once per physics tick."""

    def __init__(self, config: VehicleConfig | None = None, links: list[Link] | tuple[Link, ...] = (),
                 on_event: Callable[[AutopilotEvent], None] | None = None,
                 signing_timestamp: Callable[[], int] | None = None):
        """``signing_timestamp``: the signing clock (default: simulated time from the MAVLink epoch, for
        deterministic lockstep runs; real-time servers pass mavlink_signing.wall_timestamp)."""
        self.config = config = config or VehicleConfig()
        self.dt_s = 1.0 / config.physics_rate_hz
        self.tick = 0
        self.frame = LocalFrame(config.home)
        self.home = config.home  # the autopilot's home (geodetic); moves when the autopilot re-sets it
        self.origin_ned = (0.0, 0.0, 0.0)  # LOCAL_POSITION_NED's origin in the simulator's frame (the EKF origin)
        self.state = dynamics.VehicleState(battery_wh=config.airframe.battery_capacity_wh)
        self.command = dynamics.HOVER
        self.ground_velocity = (0.0, 0.0, 0.0)
        self.yaw_rate_rad_s = 0.0
        self.power_w = 0.0
        self.sensors = SensorSuite(config.sensors, seed=config.seed)
        self.is_ardupilot = config.autopilot == "ardupilot"
        self.telemetry_profile = resolve_profile(config.telemetry_profile, config.autopilot)
        self.params = make_params(config)
        self.system_id = self._boot_system_id()
        self.autopilot = make_autopilot(config, self.params, self.frame)
        self.links = list(links)
        self.endpoints = self._make_endpoints()
        self.on_event = on_event
        self._statustext_id = 0  # PX4: the next STATUSTEXT's id; ArduPilot: the last id given to a long one
        self.unhandled: dict[str, int] = {}
        self.handler_errors = 0
        self.signing_timestamp = signing_timestamp or simulated_timestamp(lambda: self.time_s)
        self.signing: LinkSigning | None = None
        self.setup_signing_refused = 0
        if config.signing_key is not None:
            self._enable_signing(config.signing_key)
        # PX4's mission protocol: the stored mission, fence and rally points outlive a reboot, as PX4's dataman does
        self.missions: MissionTransfer | None = None if self.is_ardupilot else MissionTransfer(
            on_mission=lambda items, current: self.autopilot.load_mission(items, current, self.time_s, self.state),
            on_fence=lambda items: self.autopilot.load_fence(items, self.time_s, self.state),
            current_seq=lambda: self.autopilot.mission_current,
            set_current=lambda seq: self.autopilot.set_mission_current(seq, self.time_s, self.state),
            text=self._autopilot_text,
            on_rally=lambda items: self.autopilot.load_rally(items))
        self.mission_reports = telemetry.MissionReports()
        self.copter_missions: CopterMissionTransfer | None = CopterMissionTransfer(
            home=lambda: (self.home.lat_deg, self.home.lon_deg, self.home.alt_m) if self.autopilot.gps_ok else None,
            running=lambda: self.autopilot.mission_running,
            on_mission=lambda items: self.autopilot.load_auto_mission(items, self.time_s, self.state),
            set_current=lambda seq: self.autopilot.set_mission_current(seq, self.time_s, self.state),
            send_current=lambda seq: self.broadcast(telemetry.mission_current(self, seq)),
            text=self._autopilot_text,
        ) if self.is_ardupilot else None
        # ArduPilot's fence and rally storage, each with its own transfers (they too outlive a reboot)
        self.copter_transfers: CopterTransfers | None = CopterTransfers(
            self.copter_missions,
            CopterFenceTransfer(lambda items: self.autopilot.load_polyfence(items), self._autopilot_text),
            CopterRallyTransfer(lambda items: self.autopilot.load_rally(items), self._autopilot_text),
        ) if self.copter_missions is not None else None
        self._handlers = self.handlers()
        self._boot_tick = -int(round(config.boot_time_s * config.physics_rate_hz))  # the tick the autopilot booted
        self._reboot_tick = None if config.reboot_at_s is None else int(round(config.reboot_at_s / self.dt_s))
        self._down_until_tick: int | None = None
        self.reboots = 0
        self.sensors.update(0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        self.autopilot.gps_ok = self.sensors.gps is not None

    def _boot_system_id(self) -> int:
        """The system id this boot speaks as: the system-id parameter as it is now (a later PARAM_SET waits for the
        next boot, as on PX4 and ArduPilot)."""
        return int(self.params[SYSTEM_ID_PARAM[self.config.autopilot]])

    def _make_endpoints(self) -> list[Endpoint]:
        """One endpoint per link, with the profile's rates (ArduPilot: the SRn_* parameters as they are at boot)."""
        endpoints = []
        for index, link in enumerate(self.links):
            rates = link_rates_hz(self.telemetry_profile, link.name, index, self.params)
            endpoints.append(Endpoint(link, self.system_id, {**rates, **self.config.telemetry_rates_hz}, index))
        return endpoints

    # ------------------------------------------------------------------ time
    @property
    def time_s(self) -> float:
        """Simulated seconds since the simulation started (exact multiple of the tick)."""
        return self.tick * self.dt_s

    @property
    def time_since_boot_s(self) -> float:
        """Seconds since the autopilot booted (boot_time_s ahead of time_s, restarting at a reboot)."""
        return (self.tick - self._boot_tick) * self.dt_s

    @property
    def time_boot_ms(self) -> int:
        return int((self.tick - self._boot_tick) * 1000 // self.config.physics_rate_hz)

    @property
    def powered(self) -> bool:
        """False while a reboot keeps the autopilot down (no MAVLink in or out)."""
        return self._down_until_tick is None

    def run(self, seconds: float) -> None:
        """Lockstep convenience: step for ``seconds`` of simulated time."""
        for _ in range(int(round(seconds / self.dt_s))):
            self.step()

    # ------------------------------------------------------------------ one tick
    def step(self) -> None:
        """Advance one physics tick: receive, decide, move, sense, send."""
        if self.tick == self._reboot_tick:
            self._power_off()
        if not self.powered and self.tick >= self._down_until_tick:
            self._power_on()
        now = self.time_s
        ap = self.autopilot
        if self.powered:
            for endpoint in self.endpoints:
                for data in endpoint.link.receive():
                    self.receive(endpoint, data)
            self.command = ap.guidance(now, self.state)
        else:
            for link in self.links:  # the autopilot is booting: whatever arrives is lost
                link.receive()
            self.command = dynamics.HOVER
        airframe, wind = self.config.airframe, self.config.wind
        previous_yaw = self.state.yaw_rad
        thrust = self.powered and ap.motors_running
        self.power_w = dynamics.power_w(self.state, self.command, airframe, wind, thrust)
        self.state = state = dynamics.step(self.state, self.command, airframe, wind, self.dt_s, armed=thrust)
        self.tick += 1
        self.yaw_rate_rad_s = math.remainder(state.yaw_rad - previous_yaw, math.tau) / self.dt_s
        self.ground_velocity = dynamics.ground_velocity(state, airframe, wind)
        self.sensors.update(self.time_s, (state.north_m, state.east_m, state.down_m), self.ground_velocity,
                            dynamics.attitude(state, airframe, wind))
        ap.gps_ok = self.sensors.gps is not None
        if self.powered:
            self._flush_events()
            self._send_telemetry()
            self._send_mission_status()

    def _send_statustext(self, severity: int, text: str) -> None:
        """STATUSTEXT carries 50 bytes: a longer text goes in chunks that share an id, numbered by chunk_seq (MAVLink
        readers join them), each autopilot with its own rules for ids and the last chunk (STATUSTEXT_ID_PER_TEXT)."""
        data = text.encode()
        if self.autopilot.STATUSTEXT_ID_PER_TEXT:  # PX4: msg.id = _id++ for every text, from 0; no closing chunk
            text_id, self._statustext_id = self._statustext_id, (self._statustext_id + 1) % 0x10000
            starts = range(0, len(data), STATUSTEXT_LEN)
        elif len(data) <= STATUSTEXT_LEN:
            self.broadcast(mavlink.MAVLink_statustext_message(severity, data, 0, 0))
            return
        else:  # ArduPilot: a non-zero id for long texts only; a full last chunk gets an empty one after it
            text_id = self._statustext_id = self._statustext_id % 0xFFFF + 1
            starts = range(0, len(data) + 1, STATUSTEXT_LEN)
        for seq, start in enumerate(starts):
            chunk = data[start:start + STATUSTEXT_LEN]
            self.broadcast(mavlink.MAVLink_statustext_message(severity, chunk, text_id, seq))

    def _flush_events(self) -> None:
        ap = self.autopilot
        if ap.state_changed:  # MAVSDK learns modes only from heartbeats: announce changes at once
            ap.state_changed = False
            self.broadcast(telemetry.heartbeat(self))
        for event in ap.events:
            if event.broadcast:
                self._send_statustext(event.severity, event.text)
            if self.on_event:
                self.on_event(event)
        ap.events.clear()
        if ap.home_changed:  # the autopilot moved home itself (ArduPilot at arming): announce it, as both do
            ap.home_changed = False
            self._set_home(ap.home_ned)

    def _send_telemetry(self) -> None:
        now = self.time_s
        built: dict[int, mavlink.MAVLink_message | None] = {}
        for endpoint in self.endpoints:
            for msg_id in endpoint.schedule.due(now):
                if msg_id not in built:
                    built[msg_id] = telemetry.BUILDERS[msg_id](self)
                if built[msg_id] is not None:
                    endpoint.send(built[msg_id])

    def _send_mission_status(self) -> None:
        """The mission protocol's retries, and MISSION_CURRENT / MISSION_ITEM_REACHED: PX4's paced as its mission
        manager does; ArduPilot's MISSION_ITEM_REACHED at once on every link (its MISSION_CURRENT streams with
        EXT_STAT)."""
        now, ap = self.time_s, self.autopilot
        if self.copter_transfers is not None:
            self.copter_transfers.tick(now)
            for seq in ap.auto_reached_news:
                self.broadcast(mavlink.MAVLink_mission_item_reached_message(seq))
            ap.auto_reached_news.clear()
            if ap.events:
                self._flush_events()
        if self.missions is None:
            return
        self.missions.tick(now)
        for msg in self.mission_reports.due(now, ap.mission_current, len(ap.mission_items), ap.mission_reached_news,
                                            ap.mission_state):
            self.broadcast(msg)
        if ap.events:  # the transfer's texts ("Operation timeout")
            self._flush_events()

    def _autopilot_text(self, text: str, severity: int) -> None:
        """A STATUSTEXT the autopilot sends (the mission protocols' texts)."""
        self.autopilot._event(self.time_s, text, severity)

    def broadcast(self, msg: mavlink.MAVLink_message) -> None:
        """Send one message on every link."""
        for endpoint in self.endpoints:
            endpoint.send(msg)

    def log(self, text: str) -> None:
        """Record an event that is not the autopilot's own (commands, parameters) for the operator log."""
        if self.on_event:
            self.on_event(AutopilotEvent(self.time_s, text, mavlink.MAV_SEVERITY_DEBUG, broadcast=False))

    # ------------------------------------------------------------------ home and reboots
    def _set_home(self, home_ned: tuple[float, float, float]) -> None:
        """Home at ``home_ned`` (the simulator's frame): geodetic home, the autopilot's home, HOME_POSITION sent."""
        self.autopilot.home_ned = home_ned
        if home_ned == (0.0, 0.0, 0.0):
            self.home = self.config.home
        else:
            self.home = GeoPoint(*self.frame.to_geodetic(*home_ned))
        if isinstance(self.autopilot, Px4Autopilot):
            self.autopilot.home_alt_m = self.home.alt_m  # PX4's NAV_TAKEOFF altitude is AMSL, so home's matters
        self.broadcast(telemetry.home_position(self))

    def _power_off(self) -> None:
        """The reboot starts: silence, motors off (the autopilot object is replaced at power-on)."""
        self._down_until_tick = self.tick + max(1, int(round(self.config.reboot_downtime_s / self.dt_s)))
        self._boot_tick = self.tick  # the new boot: time_boot_ms counts from here
        self.autopilot.armed = False
        self.reboots += 1
        where = "on the ground" if self.state.on_ground else "in the air"
        self.log(f"autopilot rebooting at {self.time_s:.2f} s ({where}), back in {self.config.reboot_downtime_s:g} s")

    def _power_on(self) -> None:
        """The autopilot is up again: fresh state in its boot mode, fresh MAVLink sequence numbers and streams
        (the parameters survive), and the local origin and home re-set where the vehicle is now (PX4's and
        ArduPilot's first position fix after boot sets both; airborne, that home is in the air)."""
        self._down_until_tick = None
        state = self.state
        here = (state.north_m, state.east_m, state.down_m)
        # PX4 (the one with ``missions``) resumes its stored mission at the item it was flying
        current = self.autopilot.mission_current if self.missions is not None else 0
        self.autopilot = make_autopilot(self.config, self.params, self.frame)
        self.autopilot.gps_ok = self.sensors.gps is not None
        self.mission_reports = telemetry.MissionReports()
        self.system_id = self._boot_system_id()
        self.endpoints = self._make_endpoints()
        if self.signing is not None:
            for link_id, endpoint in enumerate(self.endpoints):
                self.signing.install(endpoint.mav, link_id)
        self.origin_ned = here
        self._set_home(here)
        self.autopilot.home_changed = False  # just announced
        if self.copter_transfers is not None:  # ArduPilot keeps its mission, fence and rally points in storage too
            self.copter_transfers.cancel_uploads()
            self.autopilot.load_auto_mission(self.copter_missions.items, self.time_s, state)
            self.autopilot.load_polyfence(self.copter_transfers.fence.items)
            self.autopilot.load_rally(self.copter_transfers.rally.items)
        if self.missions is not None:  # a transfer does not survive the reboot; what is stored does
            self.missions.transfer = None
            self.autopilot.load_fence(self.missions.fence, self.time_s, state)
            self.autopilot.load_rally(self.missions.rally)
            if self.missions.items:
                self.autopilot.load_mission(self.missions.items, current, self.time_s, state)
        self.log(f"autopilot booted at {self.time_s:.2f} s; home and origin re-set at "
                 f"{here[0]:.1f} m N, {here[1]:.1f} m E, {-here[2]:.1f} m up")

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

    def _enable_signing(self, key: bytes) -> None:
        self.signing = vehicle_signing(key, self.signing_timestamp)
        for link_id, endpoint in enumerate(self.endpoints):
            self.signing.install(endpoint.mav, link_id)
