"""The runner's SEARCH state: a policy decision every step, guarded, streamed, and judged by the failsafes.

A decision is due every ``step_period_s``: the :class:`autonomy.search_pilot.SearchPilot` turns the filtered pose,
predicted to now, into the policy's action; it runs in a :class:`autonomy.search_pilot.DecisionWorker` (a thread
in real time, a simulated latency in lockstep), so a slow policy never stalls the setpoint stream. The geofence
guard (:mod:`autonomy.geofence`) may change the velocity before the stream flies it; a close look may ask for
another height, which is held with vertical velocity; the camera zoom goes out as MAV_CMD_SET_CAMERA_ZOOM.

While the runner cannot see the drone (a link outage, a stale pose: ``autonomy.failsafes.blind_reason``) it holds
(zero velocity) and takes no decision. Every tick ``autonomy.failsafes.judge_search`` says whether the search goes
on, waits for lost telemetry, ends (then the runner returns home), or resumes after the vehicle's own link-loss
failsafe (:mod:`autonomy.link_loss`): OFFBOARD is asked for again and the search carries on from the same state.

A drone flying in a fleet (``autonomy.fleet_runner``) gets its decisions from its seat in the fleet's rounds instead
(the runner's :class:`autonomy.search_pilot.DecisionSource`), waits for the others before its first one, streams
every setpoint through the separation shield (:mod:`autonomy.separation`), and when its search ends flies home on
its own layer and hands over to RTL above its home once its column is clear.
"""
from __future__ import annotations

import math
from typing import Iterator

from pymavlink.dialects.v20 import common as mavlink

from autonomy.autopilot_fence import home_offset_ne
from autonomy.failsafes import blind_reason, judge_search
from autonomy.geofence import guard_velocity
from autonomy.mission_state import MissionState
from autonomy.runner_core import MissionAborted
from autonomy.search_pilot import END_REASONS, Decision
from autonomy.separation import PUSH_MARGIN_M, Position, separated_velocity
from autonomy.setpoints import HOLD, VelocityCommand
from autonomy.takeoff_sequence import TakeoffSequence

LAYER_TOLERANCE_M = 2.0
"""A fleet drone within this of its layer's height (m) is on its layer."""
HOME_REACHED_M = 5.0
"""A fleet drone flying home on its layer hands over to RTL this close to its home (m, horizontally)."""
LANDING_CLEARANCE_WAIT_S = 120.0
"""How long a fleet drone over its home waits at most for the drones below to clear its column before RTL."""


class SearchLoop(TakeoffSequence):
    """SEARCH, and its resumption through OFFBOARD; see the module docstring."""

    def _search(self) -> Iterator[None]:
        self.worker.begin(self.clock.now(), self.mission.flight.step_period_s)
        if self.fleet is not None:
            self.streamer.shape = self._shielded
        if not self.worker.started():  # a fleet's drones start searching together
            self._event("fleet", "waiting for the other drones to reach their search altitudes")
            yield from self.wait_until(self.worker.started, self.config.takeoff_timeout_s,
                                       "the fleet's other drones at their search altitudes")
            self._last_decision_s = self.clock.now()  # decisions start now: the wait was no policy stall
        while self.search_end is None:
            now = self.clock.now()
            blind = self._blind(now)
            if blind is not None:  # no pose to act on: stop, and decide again once it is fresh
                self._wanted = None
                if self.streamer.latest != HOLD:
                    self.streamer.command(HOLD, now)
                    if self.link_loss.left_companion_s is None:  # a settling mode change says so itself
                        self._event("link", f"{blind}: holding position")
            elif self.worker.due(now):
                pose = self.estimator.predict_to(now)
                self.trajectory.append((round(now, 3), float(pose.position_ned[0]), float(pose.position_ned[1])))
                self.worker.submit(pose.position_ned[:2].copy(), now)
            decision = self.worker.poll(now)
            if decision is not None and self._blind(now) is None:
                yield from self._apply(decision, now)
            yield from self._check_failsafes(now)
            if self.search_end is None:
                yield from self.tick()
        if self.fleet is not None and self.search_end in END_REASONS:
            yield from self._return_on_layer()

    def _return_on_layer(self) -> Iterator[None]:
        """A fleet drone flies home itself, on its own layer and through the separation shield, and hands over to
        the autopilot's RTL above its home, which only descends and lands there, once the drones below are clear of
        its column: the way home crosses the other drones' paths and landing columns, and the shield acts only on
        what the runner streams. Anything amiss on
        the way (blind, a mode change, too long) hands over to RTL at once: the autopilot's return is the safer
        way home then."""
        home = self.link.home_position()
        if home is None:
            return
        home_north, home_east = home_offset_ne(self.mission, home)
        layer = self.mission.flight.altitude_m
        self._event("fleet", f"flying home on its layer ({layer:g} m) before RTL")
        self._height_target_m = layer
        speed = self.mission.flight.max_speed_mps
        north, east = self.estimator.predict_to(self.clock.now()).position_ned[:2]
        give_up = (self.clock.now() + math.hypot(north - home_north, east - home_east) / speed * 2.0
                   + 60.0 + LANDING_CLEARANCE_WAIT_S)
        waiting_said = False
        try:
            while self.clock.now() < give_up:
                now = self.clock.now()
                if self._blind(now) is not None or self.link.flight_mode != self.flavour.companion_mode:
                    return
                north, east = self.estimator.predict_to(now).position_ned[:2]
                to_north, to_east = home_north - north, home_east - east
                distance = math.hypot(to_north, to_east)
                if distance <= HOME_REACHED_M and abs(self._height_m() - layer) <= LAYER_TOLERANCE_M:
                    if self._column_clear(now):
                        return
                    if not waiting_said:
                        waiting_said = True
                        self._event("fleet", "over home: waiting for the drones below to clear its column before RTL")
                # full speed, slowing over the last seconds so as to stop over home; shielded as it goes out
                scale = min(speed, distance / 2.0) / max(distance, 1e-9)
                self._wanted = VelocityCommand(to_north * scale, to_east * scale, self._altitude_hold())
                self.streamer.command(self._wanted, now)
                yield from self.tick()
        finally:
            self._wanted = None  # RTL from here: nothing of ours to shield

    def _column_clear(self, now: float) -> bool:
        """Whether this drone may descend to land: no drone below it flies through its column (within the shield's
        reach and moving) or hovers inside the separation of it. The autopilot's landing is not shielded, so it
        starts only when nobody is in its way; a drone that comes later sees it descending and keeps away."""
        rule = self.fleet.rule
        north, east, down = (float(v) for v in self.estimator.predict_to(now).position_ned)
        reach = rule.horizontal_m + rule.lookahead_s * self.mission.flight.max_speed_mps
        for other in self.fleet.others():
            if not other.airborne or other.up_m >= -down:
                continue
            distance = math.hypot(other.north_m - north, other.east_m - east)
            moving = math.hypot(other.vn_mps, other.ve_mps) > 1.0
            if distance < rule.horizontal_m + PUSH_MARGIN_M or (moving and distance < reach):
                return False
        return True

    def _blind(self, now: float) -> str | None:
        return blind_reason(now, self.link_loss, self.estimator, self.config.link_loss.gap_s)

    def _apply(self, decision: Decision, now: float) -> Iterator[None]:
        self.decisions.append(decision)
        self.on_decision(decision)
        self._wanted = None
        if decision.end is not None:
            self.search_end = decision.end
            self.streamer.command(HOLD, now)
            return
        vn, ve = decision.velocity_ne
        if not (math.isfinite(vn) and math.isfinite(ve)):
            self.streamer.command(HOLD, now)
            self._event("failsafe", "policy returned a non-finite action: zero velocity, then RTL")
            # Stop first (the hold goes out for failsafe_hold_s), then return.
            yield from self.wait_until(lambda: self.clock.now() - now >= self.config.failsafe_hold_s,
                                       self.config.failsafe_hold_s + 1.0, "holding before RTL")
            self.search_end = "policy returned NaN"
            return
        self._last_decision_s = now
        vn, ve = self._fence_guard(vn, ve, now)
        # A close look may ask for another height (Decision.altitude_m); None: the mission's search altitude.
        wanted = decision.altitude_m
        self._height_target_m = self.mission.flight.altitude_m if wanted is None else float(wanted)
        self._wanted = VelocityCommand(vn, ve, self._altitude_hold())
        self.streamer.command(self._wanted, now)
        self._set_zoom(decision.zoom)

    def _separated(self, command: VelocityCommand, now: float) -> VelocityCommand:
        """``command`` through the fleet's separation shield (``autonomy.separation``); alone: unchanged."""
        if self.fleet is None:
            return command
        pose = self.estimator.predict_to(now)
        north, east, down = (float(v) for v in pose.position_ned)
        own = Position(self.fleet.name, north, east, -down, float(pose.velocity_ned[0]), float(pose.velocity_ned[1]))
        shielded = separated_velocity(own, command, self.fleet.others(), self.fleet.rule,
                                      self.mission.flight.max_speed_mps)
        if shielded != command:
            self.fleet.shielded += 1
        return shielded

    def _shielded(self, command: VelocityCommand, now: float) -> VelocityCommand:
        """A fleet drone's setpoint as it goes out (the streamer's ``shape``): through the shield against where the
        other drones are now, while the runner flies a command of its own (not while it holds, blind)."""
        return command if self._wanted is None else self._separated(command, now)

    def _check_failsafes(self, now: float) -> Iterator[None]:
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
            yield from self._resume(verdict.mode, verdict.evidence)
        else:
            self._event("failsafe", verdict.message)
            self.search_end = verdict.search_end

    def _resume(self, mode: str, evidence: str) -> Iterator[None]:
        """After the vehicle's own link-loss failsafe: stream again, ask for the companion mode again and carry on
        searching from the same search state (the pilot keeps it)."""
        self.link_loss.resumptions += 1
        limit = self.config.link_loss.max_resumptions
        self._event("resume", f"the vehicle's link-loss failsafe switched it to {mode} ({evidence}): resuming the "
                              f"search ({self.link_loss.resumptions} of {limit})")
        self._record(MissionState.OFFBOARD, f"resuming after the vehicle's failsafe to {mode}")
        # The link may still be half down (an uplink outage: the vehicle refuses the switch until setpoints arrive
        # again): keep asking, within the link-loss wait.
        give_up = self.clock.now() + self.config.link_loss.wait_s
        while True:
            try:
                yield from self._offboard()
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
