"""What every state of the mission runner stands on: its clock and control tick, its waits, commands and record.

Time belongs to a :class:`Clock`: in lockstep replay it is the simulated vehicle's (``advance`` steps the
vehicle one physics tick), against a real vehicle it is the wall clock (``advance`` sleeps one tick). Every
tick the runner receives telemetry (into the Kalman filter), sends its heartbeat when due, lets the setpoint
stream send when due and checks the failsafes; the states' waits are loops of ticks, so the stream never pauses.
The states are generators that yield once per tick (``yield from self.tick()``): whoever drives them moves the
clock on in between, one runner (``MissionRunner.run``) or several on one clock (a fleet).

Commands go out as COMMAND_LONG with retries and count as done on the vehicle's acknowledgement, or, when the
acknowledgement was lost, on what its heartbeat shows. Every transition and event is recorded with its time and
reason (the report's ``transitions`` and ``events``) and said (printed) as it happens.
"""
from __future__ import annotations

import math
from collections import deque
from typing import Callable, Iterator

from pymavlink.dialects.v20 import common as mavlink

from autonomy.autopilot_fence import fence_params
from autonomy.autopilots import LINK_LOSS_PARAM, PX4, AutopilotFlavour
from autonomy.clocks import Clock
from autonomy.companion_loss import companion_loss_params
from autonomy.estimator import PoseEstimator
from autonomy.link_loss import LinkLossMonitor
from autonomy.mission_state import COMPANION_STATES, MissionState
from autonomy.runner_config import RunnerConfig
from autonomy.search_pilot import Decision, DecisionSource, DecisionWorker, SearchPilot
from autonomy.separation import FleetPlace
from autonomy.setpoints import SetpointStreamer, StreamConfig, VelocityCommand
from autonomy.vehicle_connection import VehicleConnection
from autonomy.vehicle_link import enum_name
from autonomy.vehicle_time import BootTimeMap, receive_telemetry
from missions.mission import Mission


class MissionAborted(RuntimeError):
    """A state could not complete (the reason is recorded and the runner returns home if it can)."""


class RunnerCore:
    """The runner's clock, tick, waits, commands and record; the states build on it (``autonomy.runner``)."""

    def __init__(self, mission: Mission, pilot: SearchPilot, link: VehicleConnection, clock: Clock,
                 estimator: PoseEstimator, config: RunnerConfig = RunnerConfig(), threaded_policy: bool = False,
                 say: Callable[[str], None] = lambda text: None,
                 on_decision: Callable[[Decision], None] = lambda decision: None, simulated_policy_s: float = 0.0,
                 fleet: FleetPlace | None = None):
        """``say`` prints transitions and events; ``on_decision`` sees every policy decision (videos);
        ``simulated_policy_s``: in lockstep, how long a decision takes in simulated time (tests of slow policies);
        ``fleet``: this drone's place in a fleet (``autonomy.fleet_runner``): its seat in the shared decisions, its
        row of the shared search state and the separation kept from the others."""
        self.mission, self.pilot, self.link, self.clock, self.estimator = mission, pilot, link, clock, estimator
        self.config, self.say, self.on_decision = config, say, on_decision
        stream = StreamConfig(rate_hz=config.stream.rate_hz, stale_after_s=config.stream.stale_after_s,
                              max_horizontal_mps=mission.flight.max_speed_mps,
                              max_vertical_mps=config.stream.max_vertical_mps)
        self.streamer = SetpointStreamer(stream, link.send_velocity)
        self.fleet = fleet
        self.worker: DecisionSource = (fleet.seat if fleet is not None
                                       else DecisionWorker(pilot, threaded_policy, simulated_policy_s))
        self.boot_time = BootTimeMap(config.boot_time)
        self.flavour: AutopilotFlavour = PX4  # until the vehicle's heartbeat says otherwise
        self.link_loss = LinkLossMonitor(config.link_loss, self.flavour, link.send_timesync_request)
        self._texts_seen = 0
        self._link_back_s = -math.inf  # when telemetry last came back after a silence (decisions restart then)
        self._waiting_reported: str | None = None  # what the runner last said it waits for
        self._positions_seen_s: float | None = None
        self._track: deque = deque(maxlen=1024)  # (time, north, east) of recent position fixes, mission frame
        self.state: MissionState | None = None
        self.transitions: list[dict] = []
        self.events: list[dict] = []
        self.decisions: list[Decision] = []
        self.trajectory: list[tuple[float, float, float]] = []
        self.search_end: str | None = None
        self._zoom_percent: int | None = None
        self._last_decision_s = -math.inf
        self._height_target_m = mission.flight.altitude_m  # above the vehicle's home
        self._wanted: VelocityCommand | None = None  # the latest decision's command before a fleet's shield
        self.autopilot_fence: dict | None = None  # what the preflight check found (autonomy.autopilot_fence)
        self.companion_loss: dict | None = None  # ... and what the autopilot does without us (autonomy.companion_loss)
        self._record(MissionState.CONNECT, "start")

    # ------------------------------------------------------------------ bookkeeping
    def _record(self, state: MissionState, reason: str) -> None:
        """A transition to ``state``: recorded ("from" is None for the first) and said ("-> CONNECT: start")."""
        now = self.clock.now()
        self.transitions.append({"time_s": round(now, 3), "from": self.state, "to": state, "reason": reason})
        origin = "" if self.state is None else f"{self.state} "
        self.say(f"[{now:8.2f} s] {origin}-> {state}: {reason}")
        self.state = state

    def _event(self, kind: str, reason: str) -> None:
        now = self.clock.now()
        self.events.append({"time_s": round(now, 3), "event": kind, "reason": reason})
        self.say(f"[{now:8.2f} s] {kind}: {reason}")

    # ------------------------------------------------------------------ the loop
    def tick(self) -> Iterator[None]:
        """One control tick: yields while the clock moves on, then telemetry in, heartbeat and setpoints out.
        States wait with ``yield from self.tick()``."""
        yield
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
                               probing=self.state in COMPANION_STATES)
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
                   repeat: tuple[float, Callable[[], None]] | None = None) -> Iterator[None]:
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
            yield from self.tick()

    def command(self, command: int, *params: float, what: str, attempts: int | None = None,
                took_effect: Callable[[], bool] | None = None) -> Iterator[None]:
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
                yield from self.wait_until(lambda: self.link.ack_for(command, sent) is not None or done(),
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

    def height_m(self) -> float:
        """Filtered height above the vehicle's home (what a fleet's separation compares; see ``_height_m``)."""
        return self._height_m()

    def _height_m(self) -> float:
        """Filtered height above the vehicle's home (HOME_POSITION), 0 before any estimate.

        The estimator's NED frame is the mission's home point (``estimator.origin``); its altitude may differ from
        the vehicle's home (a mission file without ``alt_m``, a home set at arming). Heights are always taken above
        the vehicle's home, as the autopilot's own takeoff, RTL and relative altitude are: holding them relative to
        the mission's altitude would fly the drone into the water when the two disagree.
        """
        if self.estimator.time_s is None:
            return 0.0
        home_amsl = self.link.home_altitude_amsl()
        origin = self.estimator.origin
        offset_m = home_amsl - origin.alt_m if home_amsl is not None and origin is not None else 0.0
        return -float(self.estimator.position_ned[2]) - offset_m
