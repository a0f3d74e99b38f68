"""The mission runner: a state machine that flies a search with a trained policy over MAVLink.

    CONNECT -> PREFLIGHT -> ARM -> TAKEOFF -> OFFBOARD -> SEARCH -> RTL -> LAND -> DONE
                                                     (any failure or failsafe -> RTL, or DONE with the reason)
                                      SEARCH -> OFFBOARD -> SEARCH   (resumed after the vehicle's link-loss failsafe)

The autopilot is PX4 or ArduPilot Copter, told by the vehicle's HEARTBEAT (:mod:`autonomy.autopilots`): OFFBOARD is
PX4's OFFBOARD or ArduPilot's GUIDED, and take-off, mode requests and failsafes follow the autopilot's own rules.
Heights are above the vehicle's home (HOME_POSITION), and a mission whose launch point disagrees with that home is
refused before arming (:mod:`autonomy.preflight`), as is one the autopilot's own geofence would cut short
(:mod:`autonomy.autopilot_fence`). A link outage during SEARCH holds the drone (zero velocity) and
pauses decisions until telemetry is back; a mode change that the vehicle's own link-loss failsafe made is followed by
a resumption of the search, a pilot's mode change ends it (:mod:`autonomy.link_loss`, :mod:`autonomy.failsafes`).

Time belongs to a :class:`Clock`: in lockstep replay it is the simulated vehicle's (``advance`` steps the
vehicle one physics tick), against a real vehicle it is the wall clock (``advance`` sleeps one tick). Every
tick the runner receives telemetry (into the Kalman filter), sends its heartbeat when due, lets the setpoint
stream send when due and checks the failsafes; the states' waits are loops of ticks, so the stream never pauses.

In SEARCH a decision is due every ``step_period_s``: the :class:`autonomy.search_pilot.SearchPilot` turns the
filtered pose into the policy's action, the geofence guard may replace it, and the stream flies it. The policy
runs in a :class:`autonomy.search_pilot.DecisionWorker` (a thread in real time, a simulated latency in lockstep).
Every transition and failsafe is recorded with its reason.
"""
from __future__ import annotations

import math
from collections import deque
from typing import Callable

from pymavlink.dialects.v20 import common as mavlink

from autonomy.autopilot_fence import fence_params, home_offset_ne
from autonomy.companion_loss import companion_loss_params
from autonomy.autopilots import LINK_LOSS_PARAM, PX4, AutopilotFlavour, UnsupportedAutopilot, flavour_for
from autonomy.clocks import Clock, WallClock
from autonomy.estimator import PoseEstimator
from autonomy.failsafes import blind_reason, judge_search
from autonomy.geofence import guard_velocity
from autonomy.link_loss import LinkLossMonitor
from autonomy.mission_report import mission_report
from autonomy.preflight import describe_point, home_disagreement, judge_autopilot_settings
from autonomy.runner_config import RunnerConfig
from autonomy.search_pilot import Decision, DecisionWorker, SearchPilot
from autonomy.setpoints import HOLD, SetpointStreamer, StreamConfig, VelocityCommand
from autonomy.vehicle_connection import VehicleConnection
from autonomy.vehicle_link import enum_name
from autonomy.vehicle_time import BootTimeMap, receive_telemetry
from missions.mission import Mission

__all__ = ["Clock", "MissionAborted", "MissionRunner", "RunnerConfig", "WallClock"]

POSITION_RATE_HZ = 10.0
STREAM_REQUEST_PERIOD_S = 2.0  # before arming, missing streams and HOME_POSITION are asked for again this often


class MissionAborted(RuntimeError):
    """A state could not complete (the reason is recorded and the runner returns home if it can)."""


class MissionRunner:
    """Flies one mission; see the module docstring. ``run()`` returns the mission report (a dict)."""

    def __init__(self, mission: Mission, pilot: SearchPilot, link: VehicleConnection, clock: Clock,
                 estimator: PoseEstimator, config: RunnerConfig = RunnerConfig(), threaded_policy: bool = False,
                 say: Callable[[str], None] = lambda text: None,
                 on_decision: Callable[[Decision], None] = lambda decision: None, simulated_policy_s: float = 0.0):
        """``say`` prints transitions and events; ``on_decision`` sees every policy decision (videos);
        ``simulated_policy_s``: in lockstep, how long a decision takes in simulated time (tests of slow policies)."""
        self.mission, self.pilot, self.link, self.clock, self.estimator = mission, pilot, link, clock, estimator
        self.config, self.say, self.on_decision = config, say, on_decision
        stream = StreamConfig(rate_hz=config.stream.rate_hz, stale_after_s=config.stream.stale_after_s,
                              max_horizontal_mps=mission.flight.max_speed_mps,
                              max_vertical_mps=config.stream.max_vertical_mps)
        self.streamer = SetpointStreamer(stream, link.send_velocity)
        self.worker = DecisionWorker(pilot, threaded_policy, simulated_policy_s)
        self.boot_time = BootTimeMap(config.boot_time)
        self.flavour: AutopilotFlavour = PX4  # until the vehicle's heartbeat says otherwise
        self.link_loss = LinkLossMonitor(config.link_loss, self.flavour, link.send_timesync_request)
        self._texts_seen = 0
        self._link_back_s = -math.inf  # when telemetry last came back after a silence (decisions restart then)
        self._waiting_reported: str | None = None  # what the runner last said it waits for
        self._positions_seen_s: float | None = None
        self._track: deque = deque(maxlen=1024)  # (time, north, east) of recent position fixes, mission frame
        self.state: str | None = None
        self.transitions: list[dict] = []
        self.events: list[dict] = []
        self.decisions: list[Decision] = []
        self.trajectory: list[tuple[float, float, float]] = []
        self.search_end: str | None = None
        self._zoom_percent: int | None = None
        self._last_decision_s = -math.inf
        self._height_target_m = mission.flight.altitude_m  # above the vehicle's home
        self.autopilot_fence: dict | None = None  # what the preflight check found (autonomy.autopilot_fence)
        self.companion_loss: dict | None = None  # ... and what the autopilot does without us (autonomy.companion_loss)
        self._record("CONNECT", "start")

    # ------------------------------------------------------------------ bookkeeping
    def _record(self, state: str, reason: str) -> None:
        now = self.clock.now()
        self.transitions.append({"time_s": round(now, 3), "from": self.state, "to": state, "reason": reason})
        self.say(f"[{now:8.2f} s] {self.state} -> {state}: {reason}")
        self.state = state

    def _event(self, kind: str, reason: str) -> None:
        now = self.clock.now()
        self.events.append({"time_s": round(now, 3), "event": kind, "reason": reason})
        self.say(f"[{now:8.2f} s] {kind}: {reason}")

    # ------------------------------------------------------------------ the loop
    def tick(self) -> None:
        """One control tick: telemetry in, heartbeat and setpoints out. States call it while they wait."""
        self.clock.advance()
        messages = receive_telemetry(self.link, self.estimator, self.boot_time)
        now = self.clock.now()
        if any(msg.get_type() == "GLOBAL_POSITION_INT" for msg in messages):
            self._positions_seen_s = now
            if self.estimator.time_s is not None:  # the fix just fused: no prediction needed
                north, east = self.estimator.position_ned[:2]
                self._track.append((now, float(north), float(east)))
        texts = self.link.status_since(self._texts_seen)
        self._texts_seen = self.link.status_count
        was_down = self.link_loss.link_down()
        replies = self.link.take_timesync_replies() if self.link_loss.probe is not None else []
        self.link_loss.observe(now, self.link.last_vehicle_message_s, texts, replies,
                               probing=self.state in ("OFFBOARD", "SEARCH"))
        if was_down and not self.link_loss.link_down():
            self._link_back_s = now
        self.streamer.tick(now)

    def _judged_params(self) -> tuple[str, ...]:
        """The parameters the runner judges by: the autopilot's fence and what its link-loss failsafe does."""
        return (*fence_params(self.flavour.name), LINK_LOSS_PARAM[self.flavour.name])

    def _preflight_params(self, read: dict[str, float] | None = None) -> tuple[str, ...]:
        """The parameters the preflight checks read: the judged ones and what the autopilot does without us;
        ``read``: what has arrived, which decides whether ArduPilot's battery ones exist (companion_loss_params)."""
        return tuple(dict.fromkeys((*self._judged_params(), *companion_loss_params(self.flavour.name, read))))

    def wait_until(self, condition: Callable[[], bool], timeout_s: float, what: str,
                   repeat: tuple[float, Callable[[], None]] | None = None) -> None:
        """Tick until ``condition()``; MissionAborted after ``timeout_s``. ``repeat``: (period, action) to run at
        the start and then every period while waiting (asking again for something that may have been lost)."""
        end = self.clock.now() + timeout_s
        next_repeat = self.clock.now()
        while not condition():
            if self.clock.now() > end:
                raise MissionAborted(f"{what}: not within {timeout_s:g} s")
            if repeat is not None and self.clock.now() + 1e-9 >= next_repeat:
                repeat[1]()
                next_repeat += repeat[0]
            self.tick()

    def command(self, command: int, *params: float, what: str, attempts: int | None = None,
                took_effect: Callable[[], bool] | None = None) -> None:
        """COMMAND_LONG with retries (``attempts``, default ``command_retries``); raises MissionAborted unless
        the vehicle accepts it. ``took_effect``: what the vehicle's heartbeat shows once the command is carried
        out (armed, the new mode); it counts as acceptance when the ACK itself was lost on a lossy link."""
        name = mavlink.enums["MAV_CMD"][command].name
        attempts = attempts or self.config.command_retries
        done = took_effect or (lambda: False)
        for attempt in range(attempts):
            sent = self.clock.now()
            self.link.send_command(command, params, confirmation=min(attempt, 255))
            try:
                self.wait_until(lambda: self.link.ack_for(command, sent) is not None or done(),
                                self.config.command_timeout_s, f"{what}: no COMMAND_ACK for {name}")
            except MissionAborted:
                continue
            ack = self.link.ack_for(command, sent)
            if ack is None:  # no ACK, but the heartbeat shows it done
                return
            result = ack.result
            if result == mavlink.MAV_RESULT_ACCEPTED:
                return
            texts = "; ".join(self.link.status_texts[-2:])
            raise MissionAborted(f"{what}: {name} refused ({enum_name('MAV_RESULT', result)})"
                                 + (f": {texts}" if texts else ""))
        raise MissionAborted(f"{what}: no COMMAND_ACK for {name} after {attempts} attempts")

    # ------------------------------------------------------------------ the mission
    def run(self) -> dict:
        try:
            self._connect()
            self._preflight()
            self._arm_and_take_off()
            self._offboard()
            self._search()
            self._return_and_land("search ended: " + (self.search_end or "?"))
        except MissionAborted as exc:
            self._event("abort", str(exc))
            self._abort(str(exc))
        self.streamer.stop()
        if self.state != "DONE":
            self._record("DONE", "mission over")
        return self.report()

    def _connect(self) -> None:
        self.wait_until(lambda: self.link.discovered, self.config.connect_timeout_s, "waiting for the vehicle")
        try:
            self.flavour = flavour_for(self.link.autopilot)
        except UnsupportedAutopilot as exc:
            raise MissionAborted(str(exc)) from None
        self.link_loss = LinkLossMonitor(self.config.link_loss, self.flavour, self.link.send_timesync_request)
        self.link.request_params(self._preflight_params())  # read while the pose estimate converges
        self._record("PREFLIGHT", f"{self.link.vehicle_description()}, flown as {self.flavour.name}")

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

    def _preflight(self) -> None:
        self.wait_until(lambda: self.estimator.converged and self.link.home_position() is not None,
                        self.config.preflight_timeout_s, "waiting for a converged position estimate and home",
                        repeat=(STREAM_REQUEST_PERIOD_S, self._ask_for_telemetry))
        home = self.link.home_position()
        problem = home_disagreement(self.mission, home, self.config.home_tolerance_m,
                                    self.config.home_altitude_tolerance_m)
        if problem is not None:
            raise MissionAborted(f"refused before arming: {problem}")
        if not self.mission.home_altitude_known:
            self._event("warning", f"the mission gives no home altitude: the search altitude is held above the "
                                   f"vehicle's home ({describe_point(home)}), the search area assumed at its level")
        self._check_autopilot_settings(home)
        self._record("ARM", "pose estimate converged, home known")

    def _check_autopilot_settings(self, home) -> None:
        """The autopilot's own geofence against the mission (autonomy.autopilot_fence): refused if it would stop
        the search, a warning if there is none, recorded otherwise; and what it does if this computer goes silent
        (autonomy.companion_loss): a warning if it would hover until its battery is empty. Waits for the parameters
        that exist (ArduPilot's BATT_MONITOR 0 hides its BATT_*); a check whose parameters were not read within
        param_timeout_s is not made, with a warning."""
        def wanted() -> tuple[str, ...]:
            return self._preflight_params(self.link.params)
        try:
            self.wait_until(lambda: all(name in self.link.params for name in wanted()), self.config.param_timeout_s,
                            "reading the autopilot's fence and failsafe parameters",
                            repeat=(STREAM_REQUEST_PERIOD_S, lambda: self.link.request_params(wanted())))
        except MissionAborted:
            pass  # judged with what arrived
        judgement = judge_autopilot_settings(self.flavour.name, self.link.params, self.mission, home,
                                             self.config.fence_margin_m,
                                             self.link.companion_system_id,
                                             self.config.param_timeout_s)
        self.autopilot_fence, self.companion_loss = judgement.autopilot_fence, judgement.companion_loss
        for kind, text in judgement.events:
            self._event(kind, text)
        if judgement.refusal is not None:
            raise MissionAborted(judgement.refusal)

    def _set_mode(self, mode: str) -> None:
        """MAV_CMD_DO_SET_MODE for ``mode`` (the autopilot's own numbers), done once the heartbeat shows it."""
        self.command(mavlink.MAV_CMD_DO_SET_MODE, *self.flavour.mode_params(mode), what=f"switching to {mode}",
                     took_effect=lambda: self.link.flight_mode == mode)
        self.wait_until(lambda: self.link.flight_mode == mode, 3.0, f"{mode} in the heartbeat")

    def _arm_and_take_off(self) -> None:
        flavour, height = self.flavour, self.mission.flight.altitude_m
        if flavour.arm_mode is not None and self.link.flight_mode != flavour.arm_mode:
            self._set_mode(flavour.arm_mode)  # ArduPilot: arm and take off in GUIDED
        self.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1, what="arming", took_effect=lambda: self.link.armed)
        self._record("TAKEOFF", "armed")
        # Without a take-off mode (ArduPilot) a lost ACK shows as the climb itself.
        started = (lambda: self.link.flight_mode == flavour.takeoff_mode) if flavour.takeoff_mode else \
            (lambda: self._height_m() > 1.0)
        self.command(mavlink.MAV_CMD_NAV_TAKEOFF, *flavour.takeoff_params(self.link.home_altitude_amsl(), height),
                     what="takeoff", took_effect=started)
        self.wait_until(lambda: self._height_m() >= height - 1.5 and self.link.flight_mode != flavour.takeoff_mode,
                        self.config.takeoff_timeout_s, f"climbing to {height:g} m")
        self._record("OFFBOARD", f"at {self._height_m():.1f} m above home")

    def _offboard(self) -> None:
        if self.streamer.running:  # resuming: the stream never stopped
            self.streamer.command(HOLD, self.clock.now())
        else:
            self.streamer.start(self.clock.now(), HOLD)
        started, sent = self.clock.now(), self.streamer.sent
        self.wait_until(lambda: self.clock.now() - started >= self.config.offboard_lead_s, 10.0, "setpoint lead")
        mode = self.flavour.companion_mode
        self._set_mode(mode)
        self._record("SEARCH", f"{mode} after {self.streamer.sent - sent} setpoints")

    def _search(self) -> None:
        period = self.mission.flight.step_period_s
        next_decision = self.clock.now()
        while self.search_end is None:
            now = self.clock.now()
            blind = self._blind(now)
            if blind is not None:  # no pose to act on: stop, and decide again once it is fresh
                if self.streamer.latest != HOLD:
                    self.streamer.command(HOLD, now)
                    if self.link_loss.left_companion_s is None:  # a settling mode change says so itself
                        self._event("link", f"{blind}: holding position")
            elif now + 1e-9 >= next_decision and not self.worker.busy:
                pose = self.estimator.predict_to(now)
                self.trajectory.append((round(now, 3), float(pose.position_ned[0]), float(pose.position_ned[1])))
                self.worker.submit(pose.position_ned[:2].copy(), now)
                # One period after the scheduled decision; a decision that came late (slow policy) skips the
                # missed periods instead of a burst of back-to-back decisions, each counted as a full step.
                next_decision += period
                if next_decision <= now:
                    next_decision = now + period
            decision = self.worker.poll(now)
            if decision is not None and self._blind(now) is None:
                self._apply(decision, now)
            self._check_failsafes(now)
            if self.search_end is None:
                self.tick()

    def _blind(self, now: float) -> str | None:
        return blind_reason(now, self.link_loss, self.estimator, self.config.link_loss.gap_s)

    def _apply(self, decision: Decision, now: float) -> None:
        self.decisions.append(decision)
        self.on_decision(decision)
        if decision.end is not None:
            self.search_end = decision.end
            self.streamer.command(HOLD, now)
            return
        vn, ve = decision.velocity_ne
        if not (math.isfinite(vn) and math.isfinite(ve)):
            self.streamer.command(HOLD, now)
            self._event("failsafe", "policy returned a non-finite action: zero velocity, then RTL")
            # Stop first (the hold goes out for failsafe_hold_s), then return.
            self.wait_until(lambda: self.clock.now() - now >= self.config.failsafe_hold_s,
                            self.config.failsafe_hold_s + 1.0, "holding before RTL")
            self.search_end = "policy returned NaN"
            return
        self._last_decision_s = now
        vn, ve = self._fence_guard(vn, ve, now)
        # A close look may ask for another height (Decision.altitude_m); None: the mission's search altitude.
        wanted = decision.altitude_m
        self._height_target_m = self.mission.flight.altitude_m if wanted is None else float(wanted)
        self.streamer.command(VelocityCommand(vn, ve, self._altitude_hold()), now)
        self._set_zoom(decision.zoom)

    def _check_failsafes(self, now: float) -> None:
        """Act on ``autonomy.failsafes.judge_search``: wait for lost telemetry (said once), end or resume."""
        if self.search_end is not None:
            return
        settle = self.link_loss.left_companion_s  # decisions pause while a mode change settles: not a stall
        resumed_s = max(self._last_decision_s, self.transitions[-1]["time_s"], self._link_back_s,
                        -math.inf if settle is None else settle)
        verdict = judge_search(now, self.link, self.config, self.flavour, self.link_loss, self.boot_time, resumed_s,
                               lambda: self._from_home(now))
        if settle is not None and self.link_loss.left_companion_s is None and verdict is None:
            self._event("link", f"the vehicle is back in {self.flavour.companion_mode} by itself: searching on")
        if verdict is not None and verdict.action == "wait":
            if self._waiting_reported != (verdict.mode or ""):  # each wait said once
                self._waiting_reported = verdict.mode or ""
                self._event("link", verdict.message)
                if verdict.mode:  # settling a mode change: the parameters may have changed while the link was down
                    self.link.request_params(self._judged_params(), again=True)
            return
        self._waiting_reported = None
        if verdict is None:
            return
        if verdict.action == "resume":
            self._resume(verdict.mode, verdict.evidence)
        else:
            self._event("failsafe", verdict.message)
            self.search_end = verdict.search_end

    def _resume(self, mode: str, evidence: str) -> None:
        """After the vehicle's own link-loss failsafe: stream again, ask for the companion mode again and carry on
        searching from the same search state (the pilot keeps it)."""
        self.link_loss.resumptions += 1
        limit = self.config.link_loss.max_resumptions
        self._event("resume", f"the vehicle's link-loss failsafe switched it to {mode} ({evidence}): resuming the "
                              f"search ({self.link_loss.resumptions} of {limit})")
        self._record("OFFBOARD", f"resuming after the vehicle's failsafe to {mode}")
        # The link may still be half down (an uplink outage: the vehicle refuses the switch until setpoints arrive
        # again): keep asking, within the link-loss wait.
        give_up = self.clock.now() + self.config.link_loss.wait_s
        while True:
            try:
                self._offboard()
                return
            except MissionAborted as exc:
                if self.clock.now() + self.config.offboard_lead_s > give_up or \
                        self.link.flight_mode not in self.flavour.failsafe_modes:
                    raise
                self._event("resume-retry", f"not yet ({exc}): trying again")

    def _fence_guard(self, vn: float, ve: float, now: float) -> tuple[float, float]:
        """The command after the geofence guard (autonomy.geofence), judged from the pose predicted to ``now``."""
        north, east = self.estimator.predict_to(now).position_ned[:2]
        guarded = guard_velocity(vn, ve, north, east, self.mission.fence, self.config.fence_margin_m,
                                 self.config.fence_lookahead_s)
        if guarded != (vn, ve):
            self._event("geofence", f"command ({vn:.1f}, {ve:.1f}) m/s changed to ({guarded[0]:.1f}, "
                                    f"{guarded[1]:.1f}) m/s at ({north:.0f}, {east:.0f}) m")
        return guarded

    def _height_m(self) -> float:
        """Filtered height above the vehicle's home (HOME_POSITION), 0 before any estimate.

        The estimator's NED frame is the mission's home point (``estimator.origin``); its altitude may differ from
        the vehicle's home (a mission file without ``alt_m``, a home set at arming). Heights are always taken above
        the vehicle's home, as the autopilot's own takeoff, RTL and relative altitude are: holding them relative to
        the mission's altitude flew the drone into the water when the two disagreed.
        """
        if self.estimator.time_s is None:
            return 0.0
        home_amsl = self.link.home_altitude_amsl()
        origin = self.estimator.origin
        offset_m = home_amsl - origin.alt_m if home_amsl is not None and origin is not None else 0.0
        return -float(self.estimator.position_ned[2]) - offset_m

    def _from_home(self, now: float) -> tuple[float, float, float] | None:
        """The farthest the drone was from the vehicle's home within the link-loss evidence window (its position
        fixes, and now): north, east and the height now (m); None before home is known. An autopilot's fence may
        have sent it back (RTL) while the link was down."""
        home = self.link.home_position()
        if home is None or self.estimator.time_s is None:
            return None
        home_north, home_east = home_offset_ne(self.mission, home)
        since = now - self.config.link_loss.evidence_window_s
        fixes = [(n - home_north, e - home_east) for t, n, e in self._track if t >= since]
        north, east = self.estimator.predict_to(now).position_ned[:2]
        fixes.append((north - home_north, east - home_east))
        far_north, far_east = max(fixes, key=lambda fix: math.hypot(*fix))
        return float(far_north), float(far_east), self._height_m()

    def _altitude_hold(self) -> float:
        """Vertical velocity (NED, down positive) towards the target height above the vehicle's home."""
        return self.config.altitude_gain * (self._height_m() - self._height_target_m)

    def _set_zoom(self, zoom: float) -> None:
        """MAV_CMD_SET_CAMERA_ZOOM (zoom range, percent) only when the zoom changes by a 5 % step."""
        percent = int(round(zoom * 20)) * 5
        if percent != self._zoom_percent:
            self._zoom_percent = percent
            self.link.send_command(mavlink.MAV_CMD_SET_CAMERA_ZOOM, (mavlink.ZOOM_TYPE_RANGE, percent))

    def _return_and_land(self, reason: str) -> None:
        if not self.link.armed and self.search_end == "vehicle disarmed":
            self._record("DONE", f"{reason}: nothing left to fly home")
            self.streamer.stop()
            return
        self._record("RTL", reason)
        # The one command that must get through: keep asking until the link is back (or link_recovery_s is over).
        config = self.config
        attempts = max(config.command_retries, math.ceil(config.link_recovery_s / config.command_timeout_s))
        # RTL itself, not LAND: a vehicle that a failsafe put into LAND out over the water would ditch there.
        self.command(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, what="return to launch", attempts=attempts,
                     took_effect=lambda: self.link.flight_mode == "RTL")
        self.streamer.stop()
        self.wait_until(lambda: self.link.flight_mode == "RTL", 5.0, "RTL in the heartbeat")
        self._record("LAND", "returning")
        self.wait_until(lambda: not self.link.armed, self.config.land_timeout_s, "landing and disarm")
        self._record("DONE", "landed and disarmed")

    def _abort(self, reason: str) -> None:
        """After a failed state: return home if flying, else stop. From TAKEOFF too: a takeoff whose ACKs were
        all lost may still have flown (the vehicle then hovers where it climbed to)."""
        airborne = self._height_m() > 1.0  # on the ground the vehicle disarms itself (COM_DISARM_PRFLT)
        if self.state in ("TAKEOFF", "OFFBOARD", "SEARCH") and self.link.armed and airborne:
            try:
                self._return_and_land(f"abort: {reason}")
            except MissionAborted as exc:
                self._event("abort", str(exc))

    # ------------------------------------------------------------------ the report
    def report(self) -> dict:
        """The mission report (``autonomy.mission_report``): also what a killed run leaves behind."""
        return mission_report(self)
