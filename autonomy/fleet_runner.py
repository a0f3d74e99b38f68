"""The fleet runner: several drones, one search, one clock.

Each drone is flown by its own :class:`autonomy.runner.MissionRunner` (its own link, state machine, setpoint stream,
failsafes, fence guard and report), exactly as a single-drone mission is; what the fleet adds:

* **one clock**: :meth:`FleetRunner.run` moves every runner on by one control tick, then the clock by one tick
  (in lockstep the clock steps every simulated vehicle), so no drone's stream waits for another's;
* **shared decisions**: the drones search one :class:`missions.fleet_search.FleetSearchState` (one crew map and
  candidate list) flown by one :class:`autonomy.search_pilot.SearchPilot`. The drones start searching together,
  once every drone that is still flying is at its layer, and decide in rounds, one every step period: at a round
  each searching drone hands in its filtered position (its :class:`FleetSeat`), the round is decided for all
  (in a thread in real time, so a slow round delays decisions, never setpoints) and each seat gets its drone's
  decision. A drone that is blind at a round's time is advanced with its camera off; one whose search ended (home,
  failsafe, the find) is out of the rounds, and the fleet's planner gives its water to the others;
* **separation**: every runner's setpoints go through the shield of :mod:`autonomy.separation`, fed with the other
  drones' filtered positions; a :class:`autonomy.separation.SeparationWatch` records the closest approach.

The report (:meth:`FleetRunner.report`) holds the fleet's outcome (found or not, by which drone, when) and each
drone's own mission report.
"""
from __future__ import annotations

import dataclasses
import threading
from typing import Callable, Iterator

import numpy as np

from autonomy.clocks import Clock
from autonomy.estimator import PoseEstimator
from autonomy.mission_state import MissionState
from autonomy.runner import MissionRunner
from autonomy.runner_config import RunnerConfig
from autonomy.search_pilot import Decision, FlownPolicy, SearchPilot
from autonomy.separation import AIRBORNE_M, FleetPlace, Position, Separation, SeparationWatch
from autonomy.vehicle_connection import VehicleConnection
from missions.fleet_search import FleetSearchState
from missions.mission import Mission

_LEFT_THE_SEARCH = (MissionState.RTL, MissionState.LAND, MissionState.DONE)


class FleetDecisions:
    """The fleet's decision rounds on one shared :class:`SearchPilot` (module docstring)."""

    def __init__(self, pilot: SearchPilot, period_s: float, threaded: bool, simulated_compute_s: float = 0.0):
        self.pilot, self.period_s, self.threaded = pilot, period_s, threaded
        self.compute_time_s = simulated_compute_s
        n = pilot.state.n
        self.seats = [FleetSeat(self, row) for row in range(n)]
        self.ready = np.zeros(n, dtype=bool)
        self.out = np.zeros(n, dtype=bool)
        """Drones that will not search (any more): the start does not wait for them."""
        self.has_started = False
        self.next_round_s = 0.0
        self.rounds = 0
        self.found_at_s: float | None = None
        """When a round brought the find (a drone confirmed the victim and reached it)."""
        self.started_at_s: float | None = None
        """When the drones started searching together."""
        self._positions = np.zeros((n, 2))
        self._submitted = np.zeros(n, dtype=bool)
        self._thread: threading.Thread | None = None
        self._result: list[Decision | None] | None = None

    def settle(self, now_s: float, out: list[bool], positions: Callable[[], np.ndarray]) -> None:
        """After every tick of every runner: start the search once everyone still flying is ready, and decide a
        round when one is due and handed in. ``out``: drones that will not search (any more); ``positions()``
        (N, 2): every drone's filtered position, for the drones that hand in none this round."""
        for row, gone in enumerate(out):
            if gone:
                self.out[row] = True
        if not self.has_started:
            if self.ready.any() and np.all(self.ready | self.out):
                self.has_started, self.next_round_s = True, now_s
                self.started_at_s = now_s
            return
        if self._thread is not None:
            if self._thread.is_alive():
                return
            self._thread = None
            self._deliver(self._result, now_s)
        if now_s + 1e-9 < self.next_round_s or not self._submitted.any():
            return
        handed_in = self._submitted.copy()
        where = np.where(handed_in[:, None], self._positions, positions())
        self._submitted[:] = False
        self.rounds += 1
        self.next_round_s += self.period_s
        if self.next_round_s <= now_s:
            self.next_round_s = now_s + self.period_s
        if self.threaded:
            def work() -> None:
                self._result = self.pilot.decide_round(where, handed_in)
            self._thread = threading.Thread(target=work, name="fleet-round", daemon=True)
            self._thread.start()
        else:
            self._deliver(self.pilot.decide_round(where, handed_in), now_s + self.compute_time_s)

    @property
    def deciding(self) -> bool:
        """A round is being decided (in its thread, in real time)."""
        return self._thread is not None

    def hand_in(self, row: int, position_ne: np.ndarray) -> None:
        """Drone ``row``'s filtered position for the round that is due."""
        self._positions[row] = position_ne
        self._submitted[row] = True

    def _deliver(self, decisions: list[Decision | None], release_s: float) -> None:
        if self.found_at_s is None and any(d is not None and d.end == "victim reached" for d in decisions):
            self.found_at_s = release_s
        for seat, decision in zip(self.seats, decisions):
            if seat.waiting:
                seat.hand_back(decision, release_s)


class FleetSeat:
    """One drone's place in the fleet's decision rounds: the runner's
    :class:`autonomy.search_pilot.DecisionSource`."""

    def __init__(self, decisions: FleetDecisions, row: int):
        self.decisions, self.row = decisions, row
        self.waiting = False
        self._answer: tuple[float, Decision | None] | None = None

    def begin(self, now_s: float, period_s: float) -> None:
        self.decisions.ready[self.row] = True

    def started(self) -> bool:
        return self.decisions.has_started

    def due(self, now_s: float) -> bool:
        fleet = self.decisions
        return (fleet.has_started and now_s + 1e-9 >= fleet.next_round_s and not self.waiting
                and self._answer is None and not fleet.deciding)

    def submit(self, position_ne: np.ndarray, now_s: float) -> None:
        self.decisions.hand_in(self.row, position_ne)
        self.waiting = True

    def hand_back(self, decision: Decision | None, release_s: float) -> None:
        self.waiting = False
        self._answer = (release_s, decision)

    def poll(self, now_s: float) -> Decision | None:
        if self._answer is not None and now_s + 1e-9 >= self._answer[0]:
            decision, self._answer = self._answer[1], None
            return decision
        return None


def runner_position(name: str, runner: MissionRunner, now_s: float) -> Position | None:
    """Where a runner's filtered pose puts its drone now (mission frame), None before any estimate."""
    if runner.estimator.time_s is None:
        return None
    pose = runner.estimator.predict_to(now_s)
    north, east, down = (float(v) for v in pose.position_ned)
    return Position(name, north, east, -down, float(pose.velocity_ned[0]), float(pose.velocity_ned[1]),
                    -float(pose.velocity_ned[2]), airborne=runner.link.armed and runner.height_m() > AIRBORNE_M)


class FleetRunner:
    """Flies a fleet mission: one runner per drone on one clock (module docstring). ``truth()``: where the drones
    really are, for the separation record (the simulator's truth in a replay; default: the runners' estimates)."""

    def __init__(self, mission: Mission, names: list[str], runners: list[MissionRunner], decisions: FleetDecisions,
                 watch: SeparationWatch, truth: Callable[[], list[Position]] | None = None):
        self.mission, self.names, self.runners, self.decisions = mission, names, runners, decisions
        self.clock = runners[0].clock
        self.watch = watch
        self.truth = truth or self.estimated_positions
        self._runner_of = dict(zip(names, runners))
        self._done = [False] * len(runners)
        self._estimated: dict[str, tuple[float, Position | None]] = {}

    def estimated_positions(self) -> list[Position]:
        """Every drone as its runner sees it now."""
        return self._positions_now(self.names)

    def others(self, name: str) -> Callable[[], list[Position]]:
        """What a runner's shield is given: the other drones as their runners see them."""
        others = [other for other in self.names if other != name]
        return lambda: self._positions_now(others)

    def _positions_now(self, names: list[str]) -> list[Position]:
        """``names``' drones as their runners see them now (each worked out once a tick: several shields ask)."""
        now = self.clock.now()
        positions = []
        for name in names:
            known = self._estimated.get(name)
            if known is None or known[0] != now:
                known = self._estimated[name] = (now, runner_position(name, self._runner_of[name], now))
            if known[1] is not None:
                positions.append(known[1])
        return positions

    def run(self) -> dict:
        for _ in self.flight():
            self.clock.advance()
        return self.report()

    def flight(self) -> Iterator[None]:
        """Every runner's flight, a tick at a time, and the fleet's rounds in between."""
        flights = [runner.flight() for runner in self.runners]
        while not all(self._done):
            for i, flight in enumerate(flights):
                if not self._done[i]:
                    try:
                        next(flight)
                    except StopIteration:
                        self._done[i] = True
            now = self.clock.now()
            out = [done or runner.state in _LEFT_THE_SEARCH for done, runner in zip(self._done, self.runners)]
            self.decisions.settle(now, out, lambda: self._positions_ne(now))
            self.watch.observe(now, self.truth())
            yield

    def _positions_ne(self, now: float) -> np.ndarray:
        """(N, 2) every drone's filtered position now (its launch point before any estimate)."""
        return np.array([runner.estimator.predict_to(now).position_ned[:2] if runner.estimator.time_s is not None
                         else runner.pilot.state.scen.start[row] for row, runner in enumerate(self.runners)],
                        dtype=np.float64)

    def report(self) -> dict:
        """The fleet's report: the find, the separation record and every drone's mission report."""
        drones = []
        for name, runner in zip(self.names, self.runners):
            report = runner.report()
            report["name"] = name
            report["system_id"] = runner.link.companion_system_id
            report["separation_shield_changes"] = runner.fleet.shielded if runner.fleet is not None else 0
            drones.append(report)
        finder = next((d["name"] for d in drones if d["search_end"] == "victim reached"), None)
        state = self.decisions.pilot.state
        return {
            "fleet": True,
            "mission": self.mission.name,
            "drones": len(drones),
            "success": finder is not None,
            "found_by": finder,
            "search_rounds": self.decisions.rounds,
            "found_at_s": _rounded(self.decisions.found_at_s),
            "search_started_s": _rounded(self.decisions.started_at_s),
            "coverage_ratio": float(state.coverage_ratio[0]),
            "all_landed": all(d["transitions"][-1]["reason"] == "landed and disarmed" for d in drones),
            "separation": self.watch.summary(),
            "vehicles": drones,
        }


def _rounded(time_s: float | None) -> float | None:
    return None if time_s is None else round(time_s, 3)


def drone_missions(mission: Mission) -> list[Mission]:
    """Each drone's own mission: the scenario launched from its launch point, searched at its layer, no fleet."""
    fleet, flight = mission.fleet, mission.flight
    return [dataclasses.replace(
        mission, fleet=None,
        scenario=dataclasses.replace(mission.scenario, start_north_m=vehicle.north_m, start_east_m=vehicle.east_m),
        flight=dataclasses.replace(flight, altitude_m=fleet.search_altitude_m(i, flight.altitude_m)))
        for i, vehicle in enumerate(fleet.vehicles)]


def build_fleet(mission: Mission, policy: FlownPolicy, seed: int, links: list[VehicleConnection], clock: Clock,
                config: RunnerConfig = RunnerConfig(), say: Callable[[str], None] = lambda text: None,
                threaded: bool = False, truth: Callable[[], list[Position]] | None = None) -> FleetRunner:
    """The fleet runner of ``mission`` (it has a fleet section): one runner per drone on ``links`` (in the fleet's
    order) and ``clock``, one shared search state flown by ``policy`` (a scripted searcher flies all the drones
    together; an artifact flies each one). ``threaded``: decide rounds in a thread (real time). ``truth``: where
    the drones really are, for the separation record (default: the runners' estimates)."""
    fleet = mission.fleet
    if fleet is None:
        raise ValueError(f"{mission.name or 'the mission'} has no fleet section")
    if len(links) != len(fleet.vehicles):
        raise ValueError(f"the fleet has {len(fleet.vehicles)} drones: give one connection each, got {len(links)}")
    pilot = SearchPilot(mission, policy, seed, state=FleetSearchState(mission, seed))
    decisions = FleetDecisions(pilot, mission.flight.step_period_s, threaded=threaded)
    rule = Separation.of(fleet)
    names = [vehicle.name for vehicle in fleet.vehicles]
    runners: list[MissionRunner] = []
    fleet_runner: FleetRunner | None = None
    for row, (name, own, link) in enumerate(zip(names, drone_missions(mission), links)):
        place = FleetPlace(name, row, decisions.seats[row], rule, lambda name=name: fleet_runner.others(name)())
        runners.append(MissionRunner(own, pilot, link, clock, PoseEstimator(home=mission.scenario.home), config,
                                     say=lambda text, name=name: say(f"{name}: {text}"), fleet=place))
    fleet_runner = FleetRunner(mission, names, runners, decisions, SeparationWatch(rule), truth)
    return fleet_runner


def fleet_summary(report: dict) -> str:
    """The fleet report's one line: the find, the landings and the separation."""
    found = (f"found by {report['found_by']} at {report['found_at_s']:.0f} s" if report["success"]
             else "victim not found")
    landed = sum(d["transitions"][-1]["reason"] == "landed and disarmed" for d in report["vehicles"])
    separation = report["separation"]
    closest = separation["closest_unlayered_m"]
    kept = (f"{len(separation['breaches'])} separation breaches" if separation["breached"]
            else "separation kept" + (f" (closest on one layer {closest:.0f} m)" if closest is not None else ""))
    return (f"{report['mission']} ({report['pilot']}, {report['drones']} drones): {found}; "
            f"{landed} of {report['drones']} landed and disarmed; {kept}")
