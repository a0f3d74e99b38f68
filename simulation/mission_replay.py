"""Mission replay: the runner flies a mission against the in-process simulated vehicle, in lockstep.

Everything a real flight has is here (MAVLink 2 bytes both ways over the in-memory link, the autopilot's
rules, the Kalman filter on noisy telemetry, the setpoint stream), only the clock is the simulation's: the
runner's every tick steps the vehicle one physics tick, so a replay runs as fast as the machine allows and the
same mission, policy and seed give a byte-identical tlog and report.

Link faults (:mod:`sitl_bridge.faults`: loss, latency, duplication, reordering, outages) can be put on the vehicle's
end of the link, timed on the simulated clock and seeded by the run's seed (or their own), so a faulty replay is
as reproducible as a clean one. A :class:`simulation.flight_outcome.FlightWatch` judges every replay from the
simulator's ground truth (completed, ended safely, or flyaway; the report's ``outcome``).

Here the on-board runtime (``autonomy``) meets the simulated vehicle (``sitl_bridge``); the runtime itself never
imports the simulator, so a companion computer flying a real autopilot has no use for this module.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Callable

from autonomy.estimator import PoseEstimator
from autonomy.recorder import REPORT, TLOG, PartialReport, TlogRecorder
from autonomy.runner import MissionRunner, RunnerConfig
from autonomy.search_pilot import FlownPolicy, SearchPilot
from autonomy.vehicle_link import COMPANION_COMPONENT, VehicleLink
from missions.geodesy import GeoPoint
from missions.mission import Mission
from missions.render import render_search
from simulation.flight_outcome import FlightWatch, FlyawayLimits
from simulation.video import VideoRecorder
from sitl_bridge.dynamics import MultirotorParams
from sitl_bridge.faults import LinkFaults, apply_faults
from sitl_bridge.link import MemoryMavConnection, memory_link_pair
from sitl_bridge.vehicle import SimulatedVehicle, VehicleConfig


DEFAULT_START_TIME = datetime(2025, 1, 1, tzinfo=timezone.utc)
"""When a replay's simulated time 0 is, unless the replay is given a start time: fixed, so that two replays of the
same seed write the same bytes; the tlog's timestamps count from it (``--start-time`` on ``hrlsac mission
replay``)."""
UNIX_EPOCH = datetime(1970, 1, 1, tzinfo=timezone.utc)


def unix_microseconds(moment: datetime) -> int:
    """``moment`` (aware) in whole microseconds since the Unix epoch, as a tlog stamps its messages."""
    return (moment - UNIX_EPOCH) // timedelta(microseconds=1)


@dataclass
class VehicleClock:
    """The simulated vehicle's time; ``advance`` steps it one physics tick (then calls ``after_step``)."""

    vehicle: SimulatedVehicle
    after_step: Callable[[], None] = lambda: None

    def now(self) -> float:
        return self.vehicle.time_s

    def advance(self) -> None:
        self.vehicle.step()
        self.after_step()


def start_point(mission: Mission) -> GeoPoint:
    """Where the vehicle boots: the mission's launch point (its scenario's start, at home's altitude)."""
    return mission.launch_point


def airframe_for(mission: Mission) -> MultirotorParams:
    """The SITL multirotor with its speed limit raised to the mission's (as the environment does) and a battery
    for the whole mission at full speed plus 10 minutes (take-off, return, landing) with 50 % reserve: a real
    search is planned with the battery it needs (the default 90 Wh lasts about 14 minutes at 10 m/s)."""
    base, flight = MultirotorParams(), mission.flight
    seconds = flight.max_steps * flight.step_period_s + 600.0
    power_w = base.hover_power_w + base.power_per_airspeed2_w * flight.max_speed_mps ** 2
    return dataclasses.replace(base, max_speed_xy_mps=max(base.max_speed_xy_mps, flight.max_speed_mps),
                               battery_capacity_wh=max(base.battery_capacity_wh, 1.5 * power_w * seconds / 3600.0))


def replay_mission(mission: Mission, policy: FlownPolicy, seed: int = 0, out: Path | None = None, video: bool = True,
                   config: RunnerConfig = RunnerConfig(), vehicle_config: VehicleConfig | None = None,
                   say: Callable[[str], None] = lambda text: None, simulated_policy_s: float = 0.0,
                   link_faults: LinkFaults | None = None, limits: FlyawayLimits = FlyawayLimits(),
                   signing_key: bytes | None = None, start_time: datetime = DEFAULT_START_TIME) -> dict:
    """Fly ``mission`` once; ``seed`` drives the vehicle's sensor noise and the simulated camera's draws.
    With ``out``, writes the tlog, report (partial ones while flying), trajectory PNG and (``video``) MP4 there.
    Returns the report. ``simulated_policy_s``: simulated time each policy decision takes (0: instant; tests of
    slow policies). ``link_faults``: faults on the link, timed on the simulated clock, seeded by ``seed`` unless
    they carry their own. ``limits``: what counts as a flyaway (the report's ``outcome``). ``signing_key``: sign
    the link both ways (vehicle and runner), timestamps from simulated time so the tlog stays reproducible.
    ``start_time`` (aware): the moment simulated time 0 stands for in the tlog's timestamps."""
    vehicle_end, client_end = memory_link_pair("replay")
    vehicle_config = vehicle_config or VehicleConfig(home=start_point(mission), seed=seed,
                                                     airframe=airframe_for(mission))
    if signing_key is not None:
        vehicle_config = dataclasses.replace(vehicle_config, signing_key=signing_key)
    links = apply_faults([vehicle_end], link_faults, lambda: vehicle.time_s, seed)
    vehicle = SimulatedVehicle(vehicle_config, links, on_event=lambda event: watch.on_vehicle_event(event))
    watch = FlightWatch(vehicle, mission, limits)
    clock = VehicleClock(vehicle, watch.observe)
    run_facts = dict(**policy.describe(), seed=seed, clock="lockstep",
                     link_faults=link_faults.describe() if link_faults is not None else "none")
    tlog = pictures = None
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        tlog = TlogRecorder(out / TLOG, unix_microseconds(start_time))
        pictures = VideoRecorder(out, video)
    connection = MemoryMavConnection(client_end, source_system=1, source_component=COMPANION_COMPONENT)
    link = VehicleLink(connection, clock.now, tlog, signing_key=signing_key, warn=say)
    pilot = SearchPilot(mission, policy, seed)
    path: list[tuple[float, float]] = []

    def draw(decision) -> None:
        path.append(tuple(pilot.state.position[0]))
        if pictures is not None:
            pictures.add(render_search(pilot.state, 0, path, float(pilot.zoom[0])))

    partial = PartialReport(out / REPORT if out is not None else None,
                            lambda: {**runner.report(), **run_facts, "tlog_messages": tlog.messages})
    runner = MissionRunner(mission, pilot, link, clock, PoseEstimator(home=mission.scenario.home), config,
                           say=partial.after(say), on_decision=partial.after(draw),
                           simulated_policy_s=simulated_policy_s)
    partial.start()  # a record exists from the first moment on
    try:
        report = runner.run()
    finally:
        if tlog is not None:
            tlog.close()
        if pictures is not None:
            pictures.close()
    report.update(run_facts)
    watch.settle()
    report["outcome"] = watch.outcome(report)
    if signing_key is not None:
        report["signing"] = {"vehicle": vehicle.signing.summary() if vehicle.signing else None,
                             "runner": link.signing.summary()}
    if links[0] is not vehicle_end:
        report["link_packets"] = links[0].counts()
    if out is not None:
        report["tlog_messages"] = tlog.messages
    partial.finish(report)
    return report
