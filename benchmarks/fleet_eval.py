"""Fleet evaluation: success and P(found by t) against the fleet's size (1, 2, 4 drones) at 1 km and on the 2 km
square, for the fleet planner (``--pilot greedy_bayes``: sequential greedy on the shared map) and the shipped
single-drone policy on every drone, in lockstep fleet replay (MAVLink both ways, one simulated vehicle per drone,
the separation shield), on the same val scenarios and seeds for every cell.

Each scenario of the split gets a fleet of N drones launched 40 m apart on a line from its start (east, or west or
north when east leaves the area), 30 m separation and 10 m altitude layers. Time is counted from the moment the
drones start searching together. Every replay is also judged for safety: separation breaches (from the
simulator's truth), drones not landed and disarmed at home, drones whose search ran dry.

``--environment N`` also flies N scenarios per cell through the same shared search and pilots without MAVLink
(each drone flies exactly its decisions, as the training environment does): the planning effect alone, with many
more episodes for the same compute.

Usage: python benchmarks/fleet_eval.py [--episodes 20] [--environment 200] [--sizes 1,2,4] [--areas 1km,2km]
       [--workers 2 | --ray local] [--out benchmarks/results/fleet_eval.json]
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time

import numpy as np
import torch
from common import results_file, write_report

from autonomy.pilots import PilotChoice
from autonomy.policy import load_policy
from autonomy.search_pilot import SearchPilot
from missions.fleet import Fleet, FleetVehicle
from missions.fleet_search import FleetSearchState
from missions.generator import SPLITS
from missions.mission import FlightSettings, Mission
from policies.cli.evaluate import read_generator_config
from policies.evaluation.episodes import episode_batch
from policies.evaluation.stats import wilson_interval
from simulation.fleet_replay import FleetEpisode, fly_exactly, fly_fleet_episode
from simulation.worker_pool import add_pool_arguments, pool_from_arguments, run_tasks

AREAS = {"1km": None, "2km": "docs/results/large-area.yaml"}
"""Each area's scenario generator config (None: SarSearch-v1's own)."""
POLICY = "policies/pretrained/hrl-sac.pt"
SPACING_M = 40.0
FOUND_BY_S = (120, 240, 480)
"""The times (s after the search starts) at which P(found by t) is reported."""


def fleet_mission(scenario, flight: FlightSettings, size: int) -> Mission:
    """The scenario flown by ``size`` drones on a launch line from its start that stays inside the area."""
    area = scenario.area
    for bearing_n, bearing_e in ((0.0, 1.0), (0.0, -1.0), (1.0, 0.0), (-1.0, 0.0)):
        points = [(scenario.start_north_m + k * SPACING_M * bearing_n,
                   scenario.start_east_m + k * SPACING_M * bearing_e) for k in range(size)]
        if all(area.contains(north, east) for north, east in points):
            break
    vehicles = tuple(FleetVehicle(f"drone{k + 1}", k + 1, north, east) for k, (north, east) in enumerate(points))
    return Mission(scenario=scenario, flight=flight, name=scenario.name, fleet=Fleet(vehicles))


def fly_shared_search(mission: Mission, pilot_choice: PilotChoice, seed: int) -> dict:
    """The fleet's shared search without MAVLink (``simulation.fleet_replay.fly_exactly``)."""
    state = FleetSearchState(mission, seed)
    pilot = SearchPilot(mission, pilot_choice.load(), seed, state=state)
    ends = fly_exactly(pilot)
    found = "victim reached" in ends
    return {"success": found, "time_s": float(state.time_s[0]) if found else None,
            "ran_dry": "endurance exhausted" in ends}


def summarise_cell(outcomes: list[dict]) -> dict:
    success = np.array([o["success"] for o in outcomes])
    times = [o["time_s"] for o in outcomes if o["success"]]
    low, high = wilson_interval(int(success.sum()), len(success))
    cell = {"episodes": len(outcomes), "success_rate": float(success.mean()), "success_ci95": [low, high],
            "median_time_to_find_s": float(np.median(times)) if times else None,
            "p_found_by": {str(t): float(np.mean([o["success"] and o["time_s"] <= t for o in outcomes]))
                           for t in FOUND_BY_S}}
    for key in ("breaches", "not_home", "ran_dry"):
        if key in outcomes[0]:
            cell[key] = int(sum(o[key] for o in outcomes))
    return cell


def replay_outcome(report: dict) -> dict:
    found = report["success"]
    return {"success": found,
            "time_s": report["found_at_s"] - report["search_started_s"] if found else None,
            "breaches": len(report["separation"]["breaches"]),
            "not_home": sum(d["outcome"] != "completed" for d in report["vehicles"]),
            "ran_dry": sum(d["search_end"] == "endurance exhausted" for d in report["vehicles"])}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20, help="lockstep replays per cell")
    parser.add_argument("--environment", type=int, default=0, help="exact-flight episodes per cell (0: none)")
    parser.add_argument("--sizes", default="1,2,4")
    parser.add_argument("--areas", default="1km,2km")
    parser.add_argument("--pilots", default="greedy_bayes,policy")
    parser.add_argument("--split", default="val", choices=SPLITS)
    add_pool_arguments(parser)
    parser.add_argument("--out", default=results_file("fleet_eval.json"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    pool = pool_from_arguments(args)
    sizes = [int(size) for size in args.sizes.split(",")]
    flight = FlightSettings(**load_policy(POLICY).manifest.training_config["flight"])
    choices = {name: PilotChoice(policy=POLICY) if name == "policy" else PilotChoice(scripted=name)
               for name in args.pilots.split(",")}
    results: dict = {"replay": {}, "environment": {}}
    started = time.perf_counter()
    for area in args.areas.split(","):
        count = max(args.episodes, args.environment)
        environment = {"generator": read_generator_config(AREAS[area])} if AREAS[area] else {}
        scenarios = episode_batch(args.split, count, flight, goal_conditioned=False, task="SarSearch-v1",
                                  **environment).scenarios
        for pilot, choice in choices.items():
            for size in sizes:
                key = f"{area}/{pilot}/{size}"
                missions = [fleet_mission(scenario, flight, size) for scenario in scenarios]
                if args.episodes:
                    tasks = [FleetEpisode(mission, choice, seed) for seed, mission in
                             enumerate(missions[:args.episodes])]
                    reports = run_tasks(fly_fleet_episode, tasks, pool)
                    results["replay"][key] = summarise_cell([replay_outcome(r) for r in reports])
                    show("replay", key, results["replay"][key], started)
                if args.environment:
                    outcomes = [fly_shared_search(mission, choice, seed) for seed, mission in
                                enumerate(missions[:args.environment])]
                    results["environment"][key] = summarise_cell(outcomes)
                    show("environment", key, results["environment"][key], started)
                # after every cell: a long run that stops keeps what it measured
                write_report(args.out, {"split": args.split, "episodes": args.episodes,
                                        "environment_episodes": args.environment, "flight": dataclasses.asdict(flight),
                                        "spacing_m": SPACING_M, "pool": pool.describe(), **results,
                                        "wall_s": time.perf_counter() - started})
    return 0


def show(kind: str, key: str, cell: dict, started: float) -> None:
    low, high = cell["success_ci95"]
    extra = "".join(f"; {name} {cell[name]}" for name in ("breaches", "not_home", "ran_dry") if name in cell)
    median = cell["median_time_to_find_s"]
    print(f"{kind:11s} {key:24s} success {cell['success_rate']:6.1%} [{low:.0%}, {high:.0%}]  median find "
          f"{'-' if median is None else f'{median:.0f} s'}{extra}  ({time.perf_counter() - started:.0f} s)",
          flush=True)


if __name__ == "__main__":
    sys.exit(main())
