"""Fleet replay: a fleet mission flown against several in-process simulated vehicles, in lockstep.

One simulated vehicle per drone of the mission's fleet (system id and launch point from the fleet section, a sensor
seed of its own), each on its own in-memory MAVLink 2 link to its own runner, as PX4 SITL gives every instance its
own offboard port. One clock steps every vehicle one physics tick per control tick (:class:`FleetClock`), so the
whole fleet is deterministic: the same mission, pilot and seed write the same tlogs and report. The separation
record is taken from the simulator's truth (where the vehicles really are), not from the runners' estimates.

Written to ``out``: ``report.json`` (the fleet's report, ``autonomy.fleet_runner.FleetRunner.report``, with each
drone's ground-truth ``outcome``; rewritten while flying with ``"complete": false``) and one folder per drone (its
name) holding its ``flight.tlog``.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Callable

import numpy as np

from autonomy.fleet_runner import build_fleet, drone_missions
from autonomy.pilots import PilotChoice
from autonomy.recorder import REPORT, TLOG, PartialReport, TlogRecorder
from autonomy.runner import RunnerConfig
from autonomy.search_pilot import FlownPolicy, SearchPilot
from autonomy.separation import AIRBORNE_M, Position
from autonomy.vehicle_link import COMPANION_COMPONENT, VehicleLink
from missions.geodesy import GeoPoint, LocalFrame
from missions.mission import Mission
from simulation.flight_outcome import FlightWatch, FlyawayLimits
from simulation.mission_replay import DEFAULT_START_TIME, airframe_for, unix_microseconds
from simulation.parallel_replay import speak_mavlink2
from sitl_bridge.faults import LinkFaults, apply_faults
from sitl_bridge.link import MemoryMavConnection, memory_link_pair
from sitl_bridge.vehicle import SimulatedVehicle, VehicleConfig


class FleetClock:
    """The fleet's simulated time: ``advance`` steps every vehicle one physics tick (then ``after_step``)."""

    def __init__(self, vehicles: list[SimulatedVehicle], after_step: Callable[[], None]):
        self.vehicles, self.after_step = vehicles, after_step

    def now(self) -> float:
        return self.vehicles[0].time_s

    def advance(self) -> None:
        for vehicle in self.vehicles:
            vehicle.step()
        self.after_step()


def replay_fleet(mission: Mission, policy: FlownPolicy, seed: int = 0, out: Path | None = None,
                 config: RunnerConfig = RunnerConfig(), say: Callable[[str], None] = lambda text: None,
                 limits: FlyawayLimits = FlyawayLimits(), start_time: datetime = DEFAULT_START_TIME,
                 battery_percent: dict[str, float] | None = None,
                 link_faults: dict[str, LinkFaults] | None = None, signing_key: bytes | None = None) -> dict:
    """Fly the fleet ``mission`` once with ``policy`` (a scripted searcher flies the fleet's rows together; an
    artifact flies each drone); ``seed`` drives the vehicles' sensor noise and the cameras' draws. With ``out``,
    writes the report and each drone's tlog there. Returns the fleet's report. ``battery_percent``: drones (by
    name) that take off with a part-charged battery (a drone that has to leave early). ``link_faults``: faults on
    drones' links (by name), timed on the simulated clock, seeded by ``seed`` plus the drone's place unless they
    carry their own seed. ``signing_key``: every vehicle and runner signs its link with this key (MAVLink 2
    signing, as ``replay_mission``'s); the report counts what each side accepted and refused."""
    if mission.fleet is None:
        raise ValueError(f"{mission.name or 'the mission'} has no fleet section: fly it with replay_mission")
    fleet = mission.fleet
    missions = drone_missions(mission)
    frame = LocalFrame(mission.scenario.home)
    vehicles: list[SimulatedVehicle] = []
    watches: list[FlightWatch] = []
    links: list[VehicleLink] = []
    tlogs: list[TlogRecorder] = []
    for i, (vehicle_spec, own) in enumerate(zip(fleet.vehicles, missions)):
        lat, lon, alt = frame.to_geodetic(vehicle_spec.north_m, vehicle_spec.east_m, 0.0)
        vehicle_end, client_end = memory_link_pair(f"fleet-{vehicle_spec.name}")
        faults = (link_faults or {}).get(vehicle_spec.name)
        vehicle_links = apply_faults([vehicle_end], faults, lambda: vehicles[0].time_s, seed + i)
        vehicle = SimulatedVehicle(VehicleConfig(home=GeoPoint(lat, lon, alt), seed=seed + i,
                                                 system_id=vehicle_spec.system_id, airframe=airframe_for(own),
                                                 signing_key=signing_key),
                                   vehicle_links, on_event=lambda event, k=i: watches[k].on_vehicle_event(event))
        if battery_percent and vehicle_spec.name in battery_percent:
            charge = vehicle.config.airframe.battery_capacity_wh * battery_percent[vehicle_spec.name] / 100.0
            vehicle.state = dataclasses.replace(vehicle.state, battery_wh=charge)
        watch = FlightWatch(vehicle, own, limits)
        vehicles.append(vehicle)
        watches.append(watch)
        tlog = None
        if out is not None:
            folder = Path(out) / vehicle_spec.name
            folder.mkdir(parents=True, exist_ok=True)
            tlog = TlogRecorder(folder / TLOG, unix_microseconds(start_time))
            tlogs.append(tlog)
        connection = MemoryMavConnection(client_end, source_system=vehicle_spec.system_id,
                                         source_component=COMPANION_COMPONENT)
        links.append(VehicleLink(connection, lambda: vehicles[0].time_s, tlog, signing_key=signing_key, warn=say))

    def observe() -> None:
        for watch in watches:
            watch.observe()

    clock = FleetClock(vehicles, observe)

    def truth() -> list[Position]:
        positions = []
        for spec, vehicle in zip(fleet.vehicles, vehicles):
            state = vehicle.state
            positions.append(Position(spec.name, spec.north_m + state.north_m, spec.east_m + state.east_m,
                                      -state.down_m, state.vn_mps, state.ve_mps, -state.vd_mps,
                                      airborne=not state.on_ground and -state.down_m > AIRBORNE_M))
        return positions

    # Rewritten atomically while flying, "complete": false until the end, as a single drone's replay report is.
    partial = PartialReport(Path(out) / REPORT if out is not None else None, lambda: fleet_runner.report())
    fleet_runner = build_fleet(mission, policy, seed, links, clock, config, partial.after(say), truth=truth)
    partial.start()
    try:
        report = fleet_runner.run()
    finally:
        for tlog in tlogs:
            tlog.close()
    report.update(policy.describe(), seed=seed, clock="lockstep",
                  link_faults={name: faults.describe() for name, faults in (link_faults or {}).items()})
    for drone, watch, vehicle, link in zip(report["vehicles"], watches, vehicles, links):
        watch.settle()
        drone["outcome"] = watch.outcome(drone)
        if signing_key is not None:
            drone["signing"] = {"vehicle": vehicle.signing.summary() if vehicle.signing else None,
                                "runner": link.signing.summary()}
    report["all_completed"] = all(d["outcome"]["outcome"] == "completed" for d in report["vehicles"])
    partial.finish(report)
    return report


@dataclass(frozen=True)
class FleetEpisode:
    """One fleet replay for one worker (``simulation.worker_pool.run_tasks``): the mission, what flies, the seed."""

    mission: Mission
    pilot: PilotChoice
    seed: int
    battery_percent: dict[str, float] | None = None
    """As :func:`replay_fleet`'s."""
    link_faults: dict[str, LinkFaults] | None = None
    """As :func:`replay_fleet`'s."""
    out: Path | None = None
    """Where the worker writes the report and the tlogs (None: nothing written)."""
    signing_key: bytes | None = None
    """As :func:`replay_fleet`'s."""
    start_time: datetime = DEFAULT_START_TIME
    """As :func:`replay_fleet`'s."""


def fly_fleet_episode(episode: FleetEpisode) -> dict:
    """Fly one fleet episode (writing its files to ``episode.out`` if given); its report without the drones' event
    logs (a worker's answer stays small): each drone keeps its name, search end, outcome, whether it landed and
    disarmed, its flight time and the search endurance it had left."""
    speak_mavlink2()
    report = replay_fleet(episode.mission, episode.pilot.load(), seed=episode.seed, out=episode.out,
                          start_time=episode.start_time, battery_percent=episode.battery_percent,
                          link_faults=episode.link_faults, signing_key=episode.signing_key)
    report["vehicles"] = [{"name": d["name"], "search_end": d["search_end"], "outcome": d["outcome"]["outcome"],
                           "landed": d["transitions"][-1]["reason"] == "landed and disarmed",
                           "flight_time_s": d["flight_time_s"], "energy_left": d["energy_left"]}
                          for d in report["vehicles"]]
    return report


def fly_exactly(pilot: SearchPilot) -> list[str | None]:
    """A fleet's search without MAVLink or a vehicle: every drone flies exactly its decisions (position += velocity
    x step period, as the training environment moves it), round after round until every drone's search has ended.
    Returns each drone's end (``autonomy.search_pilot.END_REASONS``; None if the step limit came first)."""
    state, flight = pilot.state, pilot.flight
    position = state.scen.start.copy()
    ends: list[str | None] = [None] * state.n
    for _ in range(flight.max_steps + 1):
        for row, decision in enumerate(pilot.decide_round(position, np.ones(state.n, dtype=bool))):
            if decision is None:
                continue
            if decision.end is None:
                position[row] += np.array(decision.velocity_ne) * flight.step_period_s
            else:
                ends[row] = decision.end
        if not pilot.live.any():
            break
    return ends
