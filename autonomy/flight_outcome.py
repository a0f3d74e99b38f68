"""How a replayed flight ended, judged from the simulated vehicle's ground truth: completed, ended safely, or a flyaway.

Only mission replays use this (the simulator's truth is not available on a real flight). A :class:`FlightWatch`
looks at the vehicle after every physics tick of the run; when the runner is done, :meth:`FlightWatch.settle`
lets the vehicle fly on alone (no companion computer, as after a crash of the companion or a dead radio) until it
is disarmed or has held position for a while, so the outcome includes what the autopilot's own failsafes did.

Outcomes:

* ``completed``: the runner went through its states to "landed and disarmed" with no failsafe and no abort, and
  the vehicle raised no failsafe of its own that the runner did not resume the search from (a link-loss failsafe
  followed by a resumption, autonomy.link_loss, is part of a completed search).
* ``safe``: something went wrong (a runner failsafe or abort, a vehicle failsafe) but the vehicle ended landed and
  disarmed, returning (RTL), landing, or holding position (HOLD or POSCTL); ``reason`` says what went wrong first.
* ``ditched``: the vehicle touched the surface farther than ``FlyawayLimits.home_radius_m`` from home, in any mode
  (over a search area at sea that is the loss of the drone, whatever the autopilot thought it was doing); it
  outranks ``safe`` and ``completed``: a drone that descended into the water is not an end state to grade safe.
* ``flyaway``: the vehicle went more than ``FlyawayLimits.fence_excursion_m`` beyond the geofence, or kept flying
  OFFBOARD with no fresh setpoint for longer than ``FlyawayLimits.stale_setpoint_s`` (PX4's default offboard-loss
  time plus half a second: a vehicle whose failsafe was set later, or off, is caught too), or was still flying in
  another mode when the settling time ran out.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from missions.mission import Mission
from missions.validation import check_fields
from sitl_bridge.autopilot import AutopilotEvent
from sitl_bridge.px4_modes import FlightMode
from sitl_bridge.vehicle import SimulatedVehicle

HOLDING_MODES = (FlightMode.HOLD, FlightMode.POSCTL)
RETURNING_MODES = (FlightMode.RTL, FlightMode.LAND)


@dataclass(frozen=True)
class FlyawayLimits:
    """What counts as a flyaway and how long the vehicle flies on alone after the runner ends."""

    fence_excursion_m: float = 50.0
    """The vehicle beyond the geofence by more than this (m, true position) is a flyaway."""
    stale_setpoint_s: float = 1.5
    """Flying OFFBOARD with no setpoint for longer than this (s) is a flyaway (PX4's offboard-loss failsafe acts
    after COM_OF_LOSS_T, 1 s by default)."""
    settle_s: float = 600.0
    """After the runner ends, the vehicle flies on alone at most this long (s, simulated)."""
    hold_settle_s: float = 10.0
    """...and stops earlier once it has held position (HOLD/POSCTL) this long (s): a hover is its end state."""
    home_radius_m: float = 10.0
    """Touching the surface farther than this from home (m, true position) is ditching."""

    def __post_init__(self) -> None:
        check_fields(self, (("fence_excursion_m", 0.0, 10_000.0), ("stale_setpoint_s", 0.1, 60.0),
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
        self.flyaway: str | None = None
        self.ditched: str | None = None
        self.settled_s = 0.0

    def on_vehicle_event(self, event: AutopilotEvent) -> None:
        """The vehicle's event hook: keep its failsafes (their text names the trigger and the action)."""
        if event.text.startswith("Failsafe"):
            self.vehicle_failsafes.append({"time_s": round(event.time_s, 3), "reason": event.text})

    def observe(self) -> None:
        vehicle, limits = self.vehicle, self.limits
        state, autopilot, now = vehicle.state, vehicle.autopilot, vehicle.time_s
        north_min, north_max, east_min, east_max = self._fence
        excursion = max(0.0, north_min - state.north_m, state.north_m - north_max,
                        east_min - state.east_m, state.east_m - east_max)
        self.max_fence_excursion_m = max(self.max_fence_excursion_m, excursion)
        if excursion > limits.fence_excursion_m and self.flyaway is None:
            self.flyaway = f"{excursion:.0f} m beyond the geofence at {now:.1f} s"
        from_home_m = math.hypot(state.north_m, state.east_m)
        if state.on_ground and from_home_m > limits.home_radius_m and self.ditched is None:
            self.ditched = f"touched the surface {from_home_m:.0f} m from home at {now:.1f} s in {autopilot.mode.name}"
        if autopilot.armed and autopilot.mode is FlightMode.OFFBOARD and not state.on_ground:
            gap = now - autopilot.setpoint.time_s if autopilot.setpoint else now
            self.longest_offboard_gap_s = max(self.longest_offboard_gap_s, gap)
            if gap > limits.stale_setpoint_s and self.flyaway is None:
                self.flyaway = f"flying OFFBOARD with no setpoint for {gap:.1f} s at {now:.1f} s"

    def settle(self) -> None:
        """Step the vehicle alone (nobody talks to it) until disarmed, holding long enough, or out of time."""
        vehicle, limits = self.vehicle, self.limits
        start = vehicle.time_s
        holding_since = None
        while vehicle.autopilot.armed and vehicle.time_s - start < limits.settle_s:
            holding = vehicle.autopilot.mode in HOLDING_MODES
            holding_since = (holding_since if holding_since is not None else vehicle.time_s) if holding else None
            if holding_since is not None and vehicle.time_s - holding_since >= limits.hold_settle_s:
                break
            vehicle.step()
            self.observe()
        self.settled_s = round(vehicle.time_s - start, 3)

    def end_state(self) -> str:
        """The vehicle's state now, in words."""
        autopilot, state = self.vehicle.autopilot, self.vehicle.state
        if not autopilot.armed:
            return "landed and disarmed" if state.on_ground else "disarmed in the air"
        if state.on_ground:
            return f"armed on the ground in {autopilot.mode.name}"
        return f"flying in {autopilot.mode.name} at {-state.down_m:.0f} m"

    def unresumed_failsafes(self, report: dict) -> list[dict]:
        """The vehicle's failsafes after which the runner did not resume the search (each resumption answers the
        latest failsafe before it): a link-loss failsafe the search came back from does not spoil a completion."""
        resumptions = [e["time_s"] for e in report["events"] if e["event"] == "resume"]
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
        autopilot, state = self.vehicle.autopilot, self.vehicle.state
        # What went wrong, in time order (the first is the cause; a vehicle failsafe often precedes the runner's).
        problems = [(e["time_s"], f"{e['event']}: {e['reason']}") for e in report["events"]
                    if e["event"] in ("failsafe", "abort")]
        problems = [text for _, text in sorted(problems + [(f["time_s"], f"vehicle: {f['reason']}")
                                                           for f in self.unresumed_failsafes(report)],
                                               key=lambda p: p[0])]
        landed = not autopilot.armed and state.on_ground
        safe_end = landed or (autopilot.armed and autopilot.mode in HOLDING_MODES + RETURNING_MODES)
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
