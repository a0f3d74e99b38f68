"""How a replayed flight ended, judged from the simulated vehicle's ground truth: completed, ended safely, or a flyaway.

Only mission replays use this (the simulator's truth is not available on a real flight). A :class:`FlightWatch`
looks at the vehicle after every physics tick of the run; when the runner is done, :meth:`FlightWatch.settle`
lets the vehicle fly on alone (no companion computer, as after a crash of the companion or a dead radio) until it
is disarmed or has held position for a while, so the outcome includes what the autopilot's own failsafes did.

Outcomes:

* ``completed``: the runner went through its states to "landed and disarmed" with no failsafe and no abort, and
  the vehicle raised no failsafe of its own that the search did not resume from (a link-loss failsafe followed by
  a resumption, autonomy.link_loss, or by PX4's own return to OFFBOARD, is part of a completed search).
* ``safe``: something went wrong (a runner failsafe or abort, a vehicle failsafe) but the vehicle ended landed and
  disarmed, returning (RTL), landing, or holding position (PX4 HOLD or POSCTL, ArduPilot LOITER or BRAKE, or
  GUIDED stopped by its GUID_TIMEOUT); ``reason`` says what went wrong first.
* ``ditched``: the vehicle touched the surface farther than ``FlyawayLimits.home_radius_m`` from home, in any mode
  (over a search area at sea that is the loss of the drone, whatever the autopilot thought it was doing); it
  outranks ``safe`` and ``completed``: a drone that descended into the water is not an end state to grade safe.
* ``flyaway``: the vehicle went more than ``FlyawayLimits.fence_excursion_m`` beyond the geofence, or kept flying
  OFFBOARD with no fresh setpoint for longer than its COM_OF_LOSS_T (at most ``FlyawayLimits.slowest_failsafe_s``)
  plus ``FlyawayLimits.failsafe_margin_s`` (a vehicle whose failsafe was set later than that, or off, is caught
  too; a 3 s COM_OF_LOSS_T is a configured choice, flown as such), or kept moving in GUIDED
  with no fresh setpoint for longer than its GUID_TIMEOUT plus ``FlyawayLimits.guided_stop_margin_s`` (by then
  ArduPilot must have stopped it), or was still flying in another mode when the settling time ran out.

The watch reads the vehicle's personality-neutral status (``vehicle.autopilot.status``: armed, phase, last
setpoint), so PX4 and ArduPilot flights are judged by the same rules.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

from missions.mission import Mission
from missions.validation import check_fields
from sitl_bridge.autopilot_base import AutopilotEvent
from sitl_bridge.vehicle import SimulatedVehicle

SAFE_PHASES = ("holding", "returning", "landing")
"""Phases (autopilot_base.FlightStatus.phase) an armed vehicle may end in safely."""
FAILSAFE_TEXT = re.compile(r"^(Failsafe: |GCS Failsafe(?! Cleared)|Battery Failsafe|.* fences? breached$)")
"""The vehicle's own failsafes in its log: the PX4 personality's "Failsafe: <cause>, switching to <mode>" (its log
line; over MAVLink PX4 says only "Failsafe activated"), ArduPilot's "GCS Failsafe", "Battery Failsafe" (not the
"GCS Failsafe Cleared" that ends one) and "Circle fence breached"."""
FALLBACK_CLEARED = "Offboard setpoints back"
"""The PX4 personality's log line when its offboard-loss fallback clears (sitl_bridge.px4.autopilot)."""
STOPPED_MPS = 0.5


@dataclass(frozen=True)
class FlyawayLimits:
    """What counts as a flyaway and how long the vehicle flies on alone after the runner ends."""

    fence_excursion_m: float = 50.0
    """The vehicle beyond the geofence by more than this (m, true position) is a flyaway."""
    failsafe_margin_s: float = 0.5
    """Flying OFFBOARD with no setpoint for longer than the vehicle's COM_OF_LOSS_T plus this (s) is a flyaway:
    PX4's offboard-loss failsafe acts after COM_OF_LOSS_T (1 s by default, so 1.5 s)."""
    slowest_failsafe_s: float = 5.0
    """...but a COM_OF_LOSS_T above this (s) counts as this: an offboard-loss failsafe later than 5 s (or one set
    to 60 s, i.e. off in practice) lets a vehicle fly on blind for too long to be an acceptable set-up."""
    guided_stop_margin_s: float = 5.0
    """Still moving in GUIDED with no setpoint for longer than GUID_TIMEOUT plus this (s) is a flyaway: ArduPilot
    stops the vehicle after GUID_TIMEOUT (3 s by default), and stopping from 20 m/s at 5 m/s^2 takes 4 s."""
    settle_s: float = 600.0
    """After the runner ends, the vehicle flies on alone at most this long (s, simulated)."""
    hold_settle_s: float = 10.0
    """...and stops earlier once it has held position (HOLD/POSCTL) this long (s): a hover is its end state."""
    home_radius_m: float = 10.0
    """Touching the surface farther than this from home (m, true position) is ditching."""

    def __post_init__(self) -> None:
        check_fields(self, (("fence_excursion_m", 0.0, 10_000.0), ("failsafe_margin_s", 0.1, 60.0),
                            ("slowest_failsafe_s", 0.1, 60.0),
                            ("guided_stop_margin_s", 0.1, 60.0),
                            ("settle_s", 0.0, 7200.0), ("hold_settle_s", 0.0, 600.0),
                            ("home_radius_m", 0.0, 10_000.0)))


class FlightWatch:
    """Ground-truth watch of one replay; call :meth:`observe` after every vehicle tick."""

    def __init__(self, vehicle: SimulatedVehicle, mission: Mission, limits: FlyawayLimits = FlyawayLimits()):
        self.vehicle, self.limits = vehicle, limits
        fence, scenario = mission.fence, mission.scenario
        # The vehicle's NED origin is the mission's start point; the fence is relative to the scenario's home.
        self._fence = (fence.north_min_m - scenario.start_north_m, fence.north_max_m - scenario.start_north_m,
                       fence.east_min_m - scenario.start_east_m, fence.east_max_m - scenario.start_east_m)
        self.max_fence_excursion_m = 0.0
        self.longest_offboard_gap_s = 0.0
        self.vehicle_failsafes: list[dict] = []
        self.fallbacks_cleared: list[float] = []  # PX4 back in OFFBOARD by itself after an offboard-loss fallback
        self.flyaway: str | None = None
        self.ditched: str | None = None
        self.settled_s = 0.0
        self._guided_since: float | None = None

    def on_vehicle_event(self, event: AutopilotEvent) -> None:
        """The vehicle's event hook: keep its failsafes (their text names the trigger and the action)."""
        if FAILSAFE_TEXT.match(event.text):
            self.vehicle_failsafes.append({"time_s": round(event.time_s, 3), "reason": event.text})
        elif event.text.startswith(FALLBACK_CLEARED):
            self.fallbacks_cleared.append(event.time_s)

    def _setpoint_gap_s(self) -> float:
        """How long the vehicle has flown its companion's setpoints without a new one (0 when not guided), counted
        from when it entered the mode at the latest (what it flies on entry is its own stop or hold)."""
        status, state = self.vehicle.autopilot.status, self.vehicle.state
        if not (status.armed and status.companion_in_control and not state.on_ground):
            self._guided_since = None
            return 0.0
        if self._guided_since is None:
            self._guided_since = self.vehicle.time_s
        last = status.last_setpoint_s if status.last_setpoint_s is not None else -math.inf
        return self.vehicle.time_s - max(last, self._guided_since)

    def _moving(self) -> bool:
        state = self.vehicle.state
        return math.hypot(state.vn_mps, state.ve_mps, state.vd_mps) > STOPPED_MPS

    def observe(self) -> None:
        vehicle, limits = self.vehicle, self.limits
        state, status, now = vehicle.state, vehicle.autopilot.status, vehicle.time_s
        north_min, north_max, east_min, east_max = self._fence
        excursion = max(0.0, north_min - state.north_m, state.north_m - north_max,
                        east_min - state.east_m, state.east_m - east_max)
        self.max_fence_excursion_m = max(self.max_fence_excursion_m, excursion)
        if excursion > limits.fence_excursion_m and self.flyaway is None:
            self.flyaway = f"{excursion:.0f} m beyond the geofence at {now:.1f} s"
        from_home_m = math.hypot(state.north_m, state.east_m)
        if state.on_ground and from_home_m > limits.home_radius_m and self.ditched is None:
            self.ditched = f"touched the surface {from_home_m:.0f} m from home at {now:.1f} s in {status.mode_name}"
        gap = self._setpoint_gap_s()
        self.longest_offboard_gap_s = max(self.longest_offboard_gap_s, gap)
        if self.flyaway is None:
            if vehicle.is_ardupilot and gap > status.setpoint_timeout_s + limits.guided_stop_margin_s \
                    and self._moving():
                self.flyaway = f"still moving in {status.mode_name} with no setpoint for {gap:.1f} s at {now:.1f} s"
            elif not vehicle.is_ardupilot and gap > min(status.setpoint_timeout_s, limits.slowest_failsafe_s) \
                    + limits.failsafe_margin_s:
                self.flyaway = f"flying {status.mode_name} with no setpoint for {gap:.1f} s at {now:.1f} s"

    def settle(self) -> None:
        """Step the vehicle alone (nobody talks to it) until disarmed, holding long enough, or out of time."""
        vehicle, limits = self.vehicle, self.limits
        start = vehicle.time_s
        holding_since = None
        while vehicle.autopilot.armed and vehicle.time_s - start < limits.settle_s:
            holding = self._holding()
            holding_since = (holding_since if holding_since is not None else vehicle.time_s) if holding else None
            if holding_since is not None and vehicle.time_s - holding_since >= limits.hold_settle_s:
                break
            vehicle.step()
            self.observe()
        self.settled_s = round(vehicle.time_s - start, 3)

    def _holding(self) -> bool:
        """Holding position: a hold mode, or (ArduPilot) GUIDED stopped after its setpoint timed out."""
        status = self.vehicle.autopilot.status
        return status.phase == "holding" or (self._setpoint_gap_s() > status.setpoint_timeout_s and not self._moving())

    def end_state(self) -> str:
        """The vehicle's state now, in words."""
        status, state = self.vehicle.autopilot.status, self.vehicle.state
        if not status.armed:
            return "landed and disarmed" if state.on_ground else "disarmed in the air"
        if state.on_ground:
            return f"armed on the ground in {status.mode_name}"
        return f"flying in {status.mode_name} at {-state.down_m:.0f} m"

    def unresumed_failsafes(self, report: dict) -> list[dict]:
        """The vehicle's failsafes after which the search did not resume (each resumption, the runner's or PX4's own
        return to OFFBOARD, answers the latest failsafe before it): a link-loss failsafe the search came back from
        does not spoil a completion."""
        resumptions = sorted([e["time_s"] for e in report["events"] if e["event"] == "resume"]
                             + self.fallbacks_cleared)
        left = []
        for failsafe in self.vehicle_failsafes:
            answer = next((t for t in resumptions if t >= failsafe["time_s"]), None)
            if answer is None:
                left.append(failsafe)
            else:
                resumptions.remove(answer)
        return left

    def outcome(self, report: dict) -> dict:
        """The outcome section of the mission report (see the module docstring)."""
        status, state = self.vehicle.autopilot.status, self.vehicle.state
        # What went wrong, in time order (the first is the cause; a vehicle failsafe often precedes the runner's).
        problems = [(e["time_s"], f"{e['event']}: {e['reason']}") for e in report["events"]
                    if e["event"] in ("failsafe", "abort")]
        problems = [text for _, text in sorted(problems + [(f["time_s"], f"vehicle: {f['reason']}")
                                                           for f in self.unresumed_failsafes(report)],
                                               key=lambda p: p[0])]
        landed = not status.armed and state.on_ground
        safe_end = landed or (status.armed and (status.phase in SAFE_PHASES or self._holding()))
        if self.flyaway is not None:
            outcome, reason = "flyaway", self.flyaway
        elif self.ditched is not None:
            outcome, reason = "ditched", self.ditched
        elif not safe_end:
            outcome, reason = "flyaway", f"still {self.end_state()} when the settling time ran out"
        elif not problems and landed and report["transitions"][-1]["reason"] == "landed and disarmed":
            outcome, reason = "completed", f"search ended: {report['search_end']}"
        else:
            outcome = "safe"
            reason = problems[0] if problems else f"search ended: {report['search_end']}"
        return {"outcome": outcome, "reason": reason, "vehicle_end": self.end_state(),
                "vehicle_failsafes": self.vehicle_failsafes,
                "max_fence_excursion_m": round(self.max_fence_excursion_m, 2),
                "longest_offboard_setpoint_gap_s": round(self.longest_offboard_gap_s, 3),
                "settled_s": self.settled_s}
