"""The runner from the first heartbeat to the companion mode: CONNECT -> PREFLIGHT -> ARM -> TAKEOFF -> OFFBOARD.

The autopilot is PX4 or ArduPilot Copter, told by the vehicle's HEARTBEAT (:mod:`autonomy.autopilots`): OFFBOARD is
PX4's OFFBOARD or ArduPilot's GUIDED, and take-off and mode requests follow the autopilot's own rules. Before
arming the runner waits for a converged pose estimate and the vehicle's home; a mission whose launch point
disagrees with that home is refused (:mod:`autonomy.preflight`), as is one the autopilot's own geofence would cut
short (:mod:`autonomy.autopilot_fence`), and what the autopilot does if this computer goes silent is checked
(:mod:`autonomy.companion_loss`). Heights are above the vehicle's home (HOME_POSITION). The setpoint stream starts
``offboard_lead_s`` before the companion mode is asked for.
"""
from __future__ import annotations

from typing import Iterator

from pymavlink.dialects.v20 import common as mavlink

from autonomy.autopilots import UnsupportedAutopilot, flavour_for
from autonomy.link_loss import LinkLossMonitor
from autonomy.mission_state import MissionState
from autonomy.preflight import describe_point, home_disagreement, judge_autopilot_settings
from autonomy.runner_core import MissionAborted, RunnerCore
from autonomy.setpoints import HOLD
from missions.geodesy import GeoPoint

POSITION_RATE_HZ = 10.0
STREAM_REQUEST_PERIOD_S = 2.0  # before arming, missing streams and HOME_POSITION are asked for again this often


class TakeoffSequence(RunnerCore):
    """The states up to the search; see the module docstring."""

    def _connect(self) -> Iterator[None]:
        yield from self.wait_until(lambda: self.link.discovered, self.config.connect_timeout_s,
                                   "waiting for the vehicle")
        try:
            self.flavour = flavour_for(self.link.autopilot)
        except UnsupportedAutopilot as exc:
            raise MissionAborted(str(exc)) from None
        self.link_loss = LinkLossMonitor(self.config.link_loss, self.flavour, self.link.send_timesync_request)
        self.link.request_params(self._preflight_params())  # read while the pose estimate converges
        self._record(MissionState.PREFLIGHT, f"{self.link.vehicle_description()}, flown as {self.flavour.name}")

    def _ask_for_telemetry(self) -> None:
        """Ask for what has not arrived yet: the position stream (ArduPilot streams nothing until asked, and a
        request is fire-and-forget: it may be lost), the battery (SYS_STATUS) and home (sent on request only)."""
        now = self.clock.now()
        if self._positions_seen_s is None or now - self._positions_seen_s > STREAM_REQUEST_PERIOD_S:
            self.link.request_message_interval(mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, POSITION_RATE_HZ)
        if self.link.battery_percent() is None:
            self.link.request_message_interval(mavlink.MAVLINK_MSG_ID_SYS_STATUS, 1.0)
        if self.link.home_position() is None:
            self.link.request_message(mavlink.MAVLINK_MSG_ID_HOME_POSITION)

    def _preflight(self) -> Iterator[None]:
        yield from self.wait_until(lambda: self.estimator.converged and self.link.home_position() is not None,
                                   self.config.preflight_timeout_s, "waiting for a converged position estimate and "
                                   "home", repeat=(STREAM_REQUEST_PERIOD_S, self._ask_for_telemetry))
        home = self.link.home_position()
        problem = home_disagreement(self.mission, home, self.config.home_tolerance_m,
                                    self.config.home_altitude_tolerance_m)
        if problem is not None:
            raise MissionAborted(f"refused before arming: {problem}")
        if not self.mission.home_altitude_known:
            self._event("warning", f"the mission gives no home altitude: the search altitude is held above the "
                                   f"vehicle's home ({describe_point(home)}), the search area assumed at its level")
        yield from self._check_autopilot_settings(home)
        self._record(MissionState.ARM, "pose estimate converged, home known")

    def _check_autopilot_settings(self, home: GeoPoint) -> Iterator[None]:
        """The autopilot's own geofence against the mission (autonomy.autopilot_fence): refused if it would stop
        the search, a warning if there is none, recorded otherwise; and what it does if this computer goes silent
        (autonomy.companion_loss): a warning if it would hover until its battery is empty. Waits for the parameters
        that exist (ArduPilot's BATT_MONITOR 0 hides its BATT_*); a check whose parameters were not read within
        param_timeout_s is not made, with a warning."""
        def wanted() -> tuple[str, ...]:
            return self._preflight_params(self.link.params)
        try:
            yield from self.wait_until(lambda: all(name in self.link.params for name in wanted()),
                                       self.config.param_timeout_s, "reading the autopilot's fence and failsafe "
                                       "parameters",
                                       repeat=(STREAM_REQUEST_PERIOD_S, lambda: self.link.request_params(wanted())))
        except MissionAborted:
            pass  # judged with what arrived
        judgement = judge_autopilot_settings(self.flavour.name, self.link.params, self.mission, home,
                                             self.config.fence_margin_m, self.link.companion_system_id,
                                             self.config.param_timeout_s)
        self.autopilot_fence, self.companion_loss = judgement.autopilot_fence, judgement.companion_loss
        for kind, text in judgement.events:
            self._event(kind, text)
        if judgement.refusal is not None:
            raise MissionAborted(judgement.refusal)

    def _set_mode(self, mode: str) -> Iterator[None]:
        """MAV_CMD_DO_SET_MODE for ``mode`` (the autopilot's own numbers), done once the heartbeat shows it."""
        yield from self.command(mavlink.MAV_CMD_DO_SET_MODE, *self.flavour.mode_params(mode),
                                what=f"switching to {mode}", took_effect=lambda: self.link.flight_mode == mode)
        yield from self.wait_until(lambda: self.link.flight_mode == mode, 3.0, f"{mode} in the heartbeat")

    def _arm_and_take_off(self) -> Iterator[None]:
        flavour, height = self.flavour, self.mission.flight.altitude_m
        if flavour.arm_mode is not None and self.link.flight_mode != flavour.arm_mode:
            yield from self._set_mode(flavour.arm_mode)  # ArduPilot: arm and take off in GUIDED
        yield from self.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1, what="arming",
                                took_effect=lambda: self.link.armed)
        self._record(MissionState.TAKEOFF, "armed")
        # Without a take-off mode (ArduPilot) a lost ACK shows as the climb itself.
        started = (lambda: self.link.flight_mode == flavour.takeoff_mode) if flavour.takeoff_mode else \
            (lambda: self._height_m() > 1.0)
        yield from self.command(mavlink.MAV_CMD_NAV_TAKEOFF,
                                *flavour.takeoff_params(self.link.home_altitude_amsl(), height), what="takeoff",
                                took_effect=started)
        yield from self.wait_until(lambda: self._height_m() >= height - 1.5
                                   and self.link.flight_mode != flavour.takeoff_mode,
                                   self.config.takeoff_timeout_s, f"climbing to {height:g} m")
        self._record(MissionState.OFFBOARD, f"at {self._height_m():.1f} m above home")

    def _offboard(self) -> Iterator[None]:
        """Stream zero velocity for ``offboard_lead_s`` (or keep the running stream at zero), then ask for the
        companion mode; SEARCH once the heartbeat shows it."""
        if self.streamer.running:  # resuming: the stream never stopped
            self.streamer.command(HOLD, self.clock.now())
        else:
            self.streamer.start(self.clock.now(), HOLD)
        started, sent = self.clock.now(), self.streamer.sent
        yield from self.wait_until(lambda: self.clock.now() - started >= self.config.offboard_lead_s, 10.0,
                                   "setpoint lead")
        mode = self.flavour.companion_mode
        yield from self._set_mode(mode)
        self._record(MissionState.SEARCH, f"{mode} after {self.streamer.sent - sent} setpoints")
