"""A fleet when things go wrong: ``missions/library/fleet-demo.yaml`` (three drones, the fleet planner) replayed in
lockstep over many seeds, clean and with one drone in trouble, judged from the simulator's truth: separation
breaches, drones lost (a flyaway, or ditched: touching the surface farther than 10 m from home), drones not landed and
disarmed, and whether the others still found the victim.

Conditions: ``clean``; ``outage`` (drone 2's link down both ways for 20 s, 120 s into the flight, mid-search);
``low_battery`` (drone 2 takes off with 28 %: the runner's low-battery failsafe brings it home early and the others
take over its water); ``lossy`` (every drone's link loses 10 % of its packets each way).

Usage: python benchmarks/fleet_faults.py [--seeds 10] [--workers 2] [--out benchmarks/results/fleet_faults.json]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from common import ROOT, results_file, write_report

from autonomy.pilots import PilotChoice
from missions.mission_file import load_mission
from simulation.fleet_replay import FleetEpisode, fly_fleet_episode
from simulation.worker_pool import add_pool_arguments, pool_from_arguments, run_tasks
from sitl_bridge.faults import parse_link_faults


def conditions(names: list[str]) -> dict[str, dict]:
    lossy = parse_link_faults("loss=0.1")
    return {"clean": {},
            "outage": {"link_faults": {"drone2": parse_link_faults("outage=120:20")}},
            "low_battery": {"battery_percent": {"drone2": 28.0}},
            "lossy": {"link_faults": {name: lossy for name in names}}}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    add_pool_arguments(parser)
    parser.add_argument("--out", default=results_file("fleet_faults.json"))
    args = parser.parse_args()
    pool = pool_from_arguments(args)
    mission = load_mission(Path(ROOT) / "missions/library/fleet-demo.yaml")
    names = [vehicle.name for vehicle in mission.fleet.vehicles]
    results, started = {}, time.perf_counter()
    for condition, options in conditions(names).items():
        tasks = [FleetEpisode(mission, PilotChoice(scripted="greedy_bayes"), seed, **options)
                 for seed in range(args.seeds)]
        reports = run_tasks(fly_fleet_episode, tasks, pool)
        results[condition] = {
            "seeds": args.seeds,
            "found": sum(r["success"] for r in reports),
            "separation_breaches": sum(len(r["separation"]["breaches"]) for r in reports),
            "closest_unlayered_m": min((r["separation"]["closest_unlayered_m"] for r in reports
                                        if r["separation"]["closest_unlayered_m"] is not None), default=None),
            "drones_lost": sum(d["outcome"] in ("flyaway", "ditched") for r in reports for d in r["vehicles"]),
            "drones_not_landed": sum(not d["landed"] for r in reports for d in r["vehicles"]),
            "search_ends": sorted({d["search_end"] for r in reports for d in r["vehicles"]}),
        }
        cell = results[condition]
        print(f"{condition:12s} found {cell['found']}/{args.seeds}; separation breaches {cell['separation_breaches']} "
              f"(closest on one layer {cell['closest_unlayered_m']} m); drones lost {cell['drones_lost']}, not "
              f"landed {cell['drones_not_landed']}; ends {cell['search_ends']}  "
              f"({time.perf_counter() - started:.0f} s)", flush=True)
    write_report(args.out, {"mission": "missions/library/fleet-demo.yaml", "pilot": "greedy_bayes",
                            "pool": pool.describe(), **results})
    return 0


if __name__ == "__main__":
    sys.exit(main())
