"""The mission runner: a state machine that flies a search with a trained policy over MAVLink.

    CONNECT -> PREFLIGHT -> ARM -> TAKEOFF -> OFFBOARD -> SEARCH -> RTL -> LAND -> DONE
                                                     (any failure or failsafe -> RTL, or DONE with the reason)

Time belongs to a :class:`Clock`: in lockstep replay it is the simulated vehicle's (``advance`` steps the
vehicle one physics tick), against a real vehicle it is the wall clock (``advance`` sleeps one tick). Every
tick the runner receives telemetry (into the Kalman filter), sends its heartbeat when due, lets the setpoint
stream send when due and checks the failsafes; the states' waits are loops of ticks, so the stream never pauses.

In SEARCH a decision is due every ``step_period_s``: the :class:`autonomy.search_pilot.SearchPilot` turns the
filtered pose into the policy's action, the geofence guard may replace it, and the stream flies it. The policy
runs in a :class:`DecisionWorker`: in real time a thread (a slow policy delays decisions, never setpoints); in
lockstep synchronously, its answer released after ``compute_time_s`` of simulated time (0 unless a test makes a
policy slow), so replays stay deterministic. Every transition and failsafe is recorded with its reason.
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from autonomy.estimator import PoseEstimator
from autonomy.preflight import describe_point, home_disagreement
from autonomy.search_pilot import Decision, SearchPilot
from autonomy.setpoints import HOLD, SetpointStreamer, StreamConfig, VelocityCommand
from autonomy.vehicle_link import VehicleLink, enum_name
from autonomy.vehicle_time import BootTimeConfig, BootTimeMap
from missions.mission import Mission
from missions.validation import check_fields

OFFBOARD_MODE = (mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 6, 0)  # PX4 main mode 6 = OFFBOARD
STATES = ("CONNECT", "PREFLIGHT", "ARM", "TAKEOFF", "OFFBOARD", "SEARCH", "RTL", "LAND", "DONE")


class Clock(Protocol):
    def now(self) -> float: ...

    def advance(self) -> None: ...


class MissionAborted(RuntimeError):
    """A state could not complete (the reason is recorded and the runner returns home if it can)."""


@dataclass(frozen=True)
class RunnerConfig:
    """Timing, limits and failsafe thresholds of the runner."""

    stream: StreamConfig = field(default_factory=StreamConfig)
    """The setpoint stream (rate, stale timeout, clamps); its horizontal clamp is set from the mission."""
    offboard_lead_s: float = 1.2
    """Setpoints streamed before OFFBOARD is requested (PX4 needs at least 1 s)."""
    connect_timeout_s: float = 15.0
    """Wait for the vehicle's first HEARTBEAT."""
    preflight_timeout_s: float = 30.0
    """Wait for a converged pose estimate and a home position."""
    takeoff_timeout_s: float = 60.0
    """Wait for the climb to the search altitude."""
    land_timeout_s: float = 600.0
    """Wait for the return, landing and disarm."""
    command_timeout_s: float = 1.5
    """Wait for one COMMAND_ACK before sending the command again."""
    command_retries: int = 3
    """Attempts per command before the runner gives up on it."""
    telemetry_timeout_s: float = 3.0
    """No vehicle message for this long = telemetry lost (failsafe)."""
    link_recovery_s: float = 60.0
    """The return command (RTL) is re-sent (every ``command_timeout_s``) for this long before the runner gives up:
    after a telemetry loss or on a lossy link, a link that comes back within it still brings the vehicle home
    (PX4 has no data-link-loss action by default)."""
    policy_stall_rtl_s: float = 5.0
    """No fresh policy decision for this long = policy stalled (failsafe: RTL)."""
    failsafe_hold_s: float = 1.0
    """After a non-finite action, zero velocity is streamed this long before RTL is requested."""
    low_battery_pct: float = 20.0
    """Battery remaining at or below this = return (failsafe: RTL)."""
    fence_margin_m: float = 20.0
    """The guard keeps the drone this far inside the geofence."""
    fence_lookahead_s: float = 2.0
    """The guard turns back when the commanded velocity would cross the margin within this time."""
    altitude_gain: float = 0.5
    """Vertical velocity per metre of altitude error (holds the search altitude above the vehicle's home)."""
    home_tolerance_m: float = 50.0
    """Largest horizontal distance between the mission's launch point and the vehicle's home (HOME_POSITION);
    farther, and the mission is refused before arming (GPS homes agree within a few metres)."""
    boot_time: BootTimeConfig = field(default_factory=BootTimeConfig)
    """How the vehicle's time_boot_ms is mapped onto the runner's clock (autonomy.vehicle_time)."""
    home_altitude_tolerance_m: float = 15.0
    """Largest difference between the mission's home altitude (when the file gives it) and the vehicle's home
    altitude, AMSL; more, and the mission is refused before arming (GPS altitude errs by a few metres)."""

    def __post_init__(self) -> None:
        check_fields(self, (("offboard_lead_s", 1.0, 10.0), ("connect_timeout_s", 0.1, 600.0),
                            ("preflight_timeout_s", 0.1, 600.0), ("takeoff_timeout_s", 1.0, 600.0),
                            ("land_timeout_s", 1.0, 3600.0), ("command_timeout_s", 0.05, 30.0),
                            ("command_retries", 1, 20), ("telemetry_timeout_s", 0.5, 60.0),
                            ("link_recovery_s", 0.0, 3600.0),
                            ("policy_stall_rtl_s", 0.5, 120.0), ("failsafe_hold_s", 0.0, 30.0),
                            ("low_battery_pct", 0.0, 100.0),
                            ("fence_margin_m", 0.0, 500.0), ("fence_lookahead_s", 0.0, 30.0),
                            ("altitude_gain", 0.01, 5.0), ("home_tolerance_m", 0.0, 10_000.0),
                            ("home_altitude_tolerance_m", 0.0, 10_000.0)), integers=("command_retries",))


class DecisionWorker:
    """Runs ``pilot.decide`` off the control loop; ``threaded`` in real time, simulated latency in lockstep."""

    def __init__(self, pilot: SearchPilot, threaded: bool, simulated_compute_s: float = 0.0):
        self.pilot, self.threaded = pilot, threaded
        self.compute_time_s = simulated_compute_s
        self._pending: tuple[float, Decision] | None = None
        self._thread: threading.Thread | None = None
        self._result: Decision | None = None

    @property
    def busy(self) -> bool:
        return self._pending is not None or (self._thread is not None and self._thread.is_alive())

    def submit(self, position_ne: np.ndarray, now_s: float) -> None:
        if self.threaded:
            def work() -> None:
                self._result = self.pilot.decide(position_ne)
            self._thread = threading.Thread(target=work, name="policy", daemon=True)
            self._thread.start()
        else:
            self._pending = (now_s + self.compute_time_s, self.pilot.decide(position_ne))

    def poll(self, now_s: float) -> Decision | None:
        """The finished decision, once (None while computing or idle)."""
        if self.threaded:
            if self._thread is not None and not self._thread.is_alive():
                self._thread, result, self._result = None, self._result, None
                return result
            return None
        if self._pending is not None and now_s + 1e-9 >= self._pending[0]:
            decision, self._pending = self._pending[1], None
            return decision
        return None


class MissionRunner:
    """Flies one mission; see the module docstring. ``run()`` returns the mission report (a dict)."""

    def __init__(self, mission: Mission, pilot: SearchPilot, link: VehicleLink, clock: Clock,
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
        self.state: str | None = None
        self.transitions: list[dict] = []
        self.events: list[dict] = []
        self.decisions: list[Decision] = []
        self.trajectory: list[tuple[float, float, float]] = []
        self.search_end: str | None = None
        self._zoom_percent: int | None = None
        self._last_decision_s = -math.inf
        self._height_target_m = mission.flight.altitude_m  # above the vehicle's home
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
        receive_telemetry(self.link, self.estimator, self.boot_time)
        self.streamer.tick(self.clock.now())

    def wait_until(self, condition: Callable[[], bool], timeout_s: float, what: str) -> None:
        end = self.clock.now() + timeout_s
        while not condition():
            if self.clock.now() > end:
                raise MissionAborted(f"{what}: not within {timeout_s:g} s")
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
        self._record("PREFLIGHT", self.link.vehicle_description())
        self.link.request_message_interval(mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 10.0)

    def _preflight(self) -> None:
        self.wait_until(lambda: self.estimator.converged and self.link.home_position() is not None,
                        self.config.preflight_timeout_s, "waiting for a converged position estimate and home")
        home = self.link.home_position()
        problem = home_disagreement(self.mission, home, self.config.home_tolerance_m,
                                    self.config.home_altitude_tolerance_m)
        if problem is not None:
            raise MissionAborted(f"refused before arming: {problem}")
        if not self.mission.home_altitude_known:
            self._event("warning", f"the mission gives no home altitude: the search altitude is held above the "
                                   f"vehicle's home ({describe_point(home)}), the search area assumed at its level")
        self._record("ARM", "pose estimate converged, home known")

    def _arm_and_take_off(self) -> None:
        self.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1, what="arming", took_effect=lambda: self.link.armed)
        self._record("TAKEOFF", "armed")
        target_amsl = self.link.home_altitude_amsl() + self.mission.flight.altitude_m
        self.command(mavlink.MAV_CMD_NAV_TAKEOFF, math.nan, 0, 0, math.nan, math.nan, math.nan, target_amsl,
                     what="takeoff", took_effect=lambda: self.link.flight_mode == "TAKEOFF")
        self.wait_until(lambda: self._height_m() >= self.mission.flight.altitude_m - 1.5
                        and self.link.flight_mode != "TAKEOFF", self.config.takeoff_timeout_s,
                        f"climbing to {self.mission.flight.altitude_m:g} m")
        self._record("OFFBOARD", f"at {self._height_m():.1f} m above home")

    def _offboard(self) -> None:
        self.streamer.start(self.clock.now(), HOLD)
        started = self.clock.now()
        self.wait_until(lambda: self.clock.now() - started >= self.config.offboard_lead_s, 10.0, "setpoint lead")
        self.command(mavlink.MAV_CMD_DO_SET_MODE, *OFFBOARD_MODE, what="switching to OFFBOARD",
                     took_effect=lambda: self.link.flight_mode == "OFFBOARD")
        self.wait_until(lambda: self.link.flight_mode == "OFFBOARD", 3.0, "OFFBOARD in the heartbeat")
        self._record("SEARCH", f"OFFBOARD after {self.streamer.sent} setpoints")

    def _search(self) -> None:
        period = self.mission.flight.step_period_s
        next_decision = self.clock.now()
        while self.search_end is None:
            now = self.clock.now()
            if now + 1e-9 >= next_decision and not self.worker.busy:
                pose = self.estimator.predict_to(now)
                self.trajectory.append((round(now, 3), float(pose.position_ned[0]), float(pose.position_ned[1])))
                self.worker.submit(pose.position_ned[:2].copy(), now)
                # One period after the scheduled decision; a decision that came late (slow policy) skips the
                # missed periods instead of a burst of back-to-back decisions, each counted as a full step.
                next_decision += period
                if next_decision <= now:
                    next_decision = now + period
            decision = self.worker.poll(now)
            if decision is not None:
                self._apply(decision, now)
            self._check_failsafes(now)
            if self.search_end is None:
                self.tick()

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
        wanted = getattr(decision, "altitude_m", None)
        self._height_target_m = self.mission.flight.altitude_m if wanted is None else float(wanted)
        self.streamer.command(VelocityCommand(vn, ve, self._altitude_hold()), now)
        self._set_zoom(decision.zoom)

    def _check_failsafes(self, now: float) -> None:
        if self.search_end is not None:
            return
        last = self.link.last_vehicle_message_s
        if last is not None and now - last > self.config.telemetry_timeout_s:
            self._event("failsafe", f"telemetry lost for {now - last:.1f} s")
            self.search_end = "telemetry lost"
        elif now - max(self._last_decision_s, self.transitions[-1]["time_s"]) > self.config.policy_stall_rtl_s:
            self._event("failsafe", f"no policy decision for {self.config.policy_stall_rtl_s:g} s: RTL")
            self.search_end = "policy stalled"
        elif (battery := self.link.battery_percent()) is not None and battery <= self.config.low_battery_pct:
            self._event("failsafe", f"battery at {battery:g} %: RTL")
            self.search_end = "low battery"
        elif self.link.flight_mode != "OFFBOARD":
            self._event("failsafe", f"the vehicle left OFFBOARD (now {self.link.flight_mode})")
            self.search_end = f"vehicle switched to {self.link.flight_mode}"

    def _fence_guard(self, vn: float, ve: float, now: float) -> tuple[float, float]:
        """Stop and turn back before the geofence: cancel any velocity component that would cross the margin
        within the lookahead, and head back inside when already beyond it. Judged from the pose predicted to
        ``now`` (the last fused telemetry is up to a message period old)."""
        fence, margin = self.mission.fence, self.config.fence_margin_m
        north, east = self.estimator.predict_to(now).position_ned[:2]
        ahead = self.config.fence_lookahead_s
        guarded = []
        for v, pos, low, high in ((vn, north, fence.north_min_m + margin, fence.north_max_m - margin),
                                  (ve, east, fence.east_min_m + margin, fence.east_max_m - margin)):
            if pos < low:
                v = max(v, 0.0) or 1.0  # turn back inside
            elif pos > high:
                v = min(v, 0.0) or -1.0
            elif not low <= pos + v * ahead <= high:
                v = 0.0
            guarded.append(v)
        if (guarded[0], guarded[1]) != (vn, ve):
            self._event("geofence", f"command ({vn:.1f}, {ve:.1f}) m/s changed to ({guarded[0]:.1f}, "
                                    f"{guarded[1]:.1f}) m/s at ({north:.0f}, {east:.0f}) m")
        return guarded[0], guarded[1]

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
        search = self.pilot.summary()
        path = np.array([(n, e) for _, n, e in self.trajectory]) if self.trajectory else np.zeros((0, 2))
        return {
            "mission": self.mission.name,
            "success": self.search_end == "victim reached",
            "search_end": self.search_end,
            **search,
            "path_length_m": float(np.hypot(*np.diff(path, axis=0).T).sum()) if len(path) > 1 else 0.0,
            "trajectory": [[t, round(n, 2), round(e, 2)] for t, n, e in self.trajectory],
            "flight_time_s": round(self.clock.now(), 3),
            "setpoints_sent": self.streamer.sent,
            "companion_heartbeats": self.link.sent_heartbeats,
            "transitions": self.transitions,
            "failsafes": [e for e in self.events if e["event"] == "failsafe"],
            "events": self.events,
            "estimator": self.estimator.counters(),
            "vehicle_time": {"offset_s": self.boot_time.offset_s, "timeline_changes": self.boot_time.timeline_changes,
                             "last_change": self.boot_time.last_change, "ignored": self.boot_time.ignored},
        }


def receive_telemetry(link: VehicleLink, estimator: PoseEstimator, boot_time: BootTimeMap) -> list:
    """Everything the vehicle sent since the last call, its positions fused into the estimator on the runner's clock
    (``boot_time`` maps their time_boot_ms; a new vehicle timeline restarts the filter). The runner's whole receive
    path: :mod:`tests.test_fuzz_mavlink` feeds it garbage."""
    messages = link.tick()
    now = link.clock()
    for msg in messages:
        if msg.get_type() == "GLOBAL_POSITION_INT":
            time_s = boot_time.to_runner_time(msg.time_boot_ms, now)
            if time_s is None:
                continue
            if boot_time.timeline_changed:
                boot_time.timeline_changed = False
                estimator.restart(boot_time.last_change)
            estimator.update_global_position_int(msg, time_s)
    return messages


class WallClock:
    """Real time for flights against a real (or real-time simulated) vehicle: ``advance`` sleeps one tick."""

    def __init__(self, tick_s: float = 0.01):
        self.tick_s = tick_s
        self._start = time.monotonic()
        self._next = self._start

    def now(self) -> float:
        return time.monotonic() - self._start

    def advance(self) -> None:
        self._next += self.tick_s
        delay = self._next - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        else:
            self._next = time.monotonic()
