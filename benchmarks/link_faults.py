"""Mission outcomes under link faults: completed, ended safely (with the reason) or flyaway, over several seeds.

Each condition is flown as a lockstep mission replay (``autonomy.replay``) with the faults on the vehicle's end of
the link, both directions, seeded by the run's seed; the outcome is judged from the simulator's ground truth
(``autonomy.flight_outcome``: flyaway = more than 50 m beyond the geofence, or OFFBOARD without a setpoint for over
1.5 s, or still flying in another mode after the vehicle was left alone). Outages start 10 s into the search (the
search start of each seed's clean run).

Usage: python benchmarks/link_faults.py [--seeds 10] [--max-steps 60]
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from collections import Counter

import torch

from autonomy.policy import load_policy
from autonomy.replay import replay_mission
from missions.mission_file import load_mission
from sitl_bridge.faults import parse_link_faults

from common import results_file, write_report

LOSS_CONDITIONS = ("loss=0", "loss=0.1", "loss=0.3", "loss=0.3,burst=5")
OUTAGE_LENGTHS_S = (0.5, 2.0, 10.0)
OUTAGE_AFTER_SEARCH_START_S = 10.0


def conditions(search_start_s: float) -> list[tuple[str, str]]:
    """(label, spec) of every condition for one seed; outages are placed in that seed's search."""
    start = round(search_start_s + OUTAGE_AFTER_SEARCH_START_S, 2)
    return [(spec, spec) for spec in LOSS_CONDITIONS] + [
        (f"outage {length:g} s", f"outage={start:g}:{length:g}") for length in OUTAGE_LENGTHS_S]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default="policies/pretrained/hrl-sac.pt")
    parser.add_argument("--mission", default="missions/library/demo.yaml")
    parser.add_argument("--max-steps", type=int, default=60, help="decisions per search (shortens the mission)")
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--out", default=results_file("link_faults.json"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    mission = load_mission(args.mission)
    mission = dataclasses.replace(mission, flight=dataclasses.replace(mission.flight, max_steps=args.max_steps))
    policy = load_policy(args.policy)
    runs: list[dict] = []
    started = time.perf_counter()
    for seed in range(args.seeds):
        clean = replay_mission(mission, policy, seed=seed, video=False)
        search_start = next((t["time_s"] for t in clean["transitions"] if t["to"] == "SEARCH"), 20.0)
        for label, spec in conditions(search_start):
            report = clean if spec == "loss=0" else replay_mission(mission, policy, seed=seed, video=False,
                                                                   link_faults=parse_link_faults(spec))
            outcome = report["outcome"]
            runs.append({"condition": label, "spec": spec, "seed": seed, "outcome": outcome["outcome"],
                         "reason": outcome["reason"], "vehicle_end": outcome["vehicle_end"],
                         "search_end": report["search_end"], "flight_time_s": report["flight_time_s"],
                         "max_fence_excursion_m": outcome["max_fence_excursion_m"],
                         "longest_offboard_setpoint_gap_s": outcome["longest_offboard_setpoint_gap_s"]})
            print(f"  seed {seed} {label:18s} {outcome['outcome']:9s} {outcome['reason']} "
                  f"[{outcome['vehicle_end']}]  ({time.perf_counter() - started:.0f} s)", file=sys.stderr)
    table = summarise(runs)
    write_report(args.out, {"mission": args.mission, "max_steps": args.max_steps, "policy": args.policy,
                            "seeds": args.seeds, "table": table, "runs": runs})
    return 0


def summarise(runs: list[dict]) -> dict[str, dict]:
    """Per condition: counts of each outcome and of each safe-end reason; printed as a table."""
    table: dict[str, dict] = {}
    for run in runs:
        row = table.setdefault(run["condition"], {"runs": 0, "completed": 0, "safe": 0, "flyaway": 0,
                                                  "safe_reasons": Counter(), "flyaway_reasons": Counter(),
                                                  "vehicle_ends": Counter()})
        row["runs"] += 1
        row[run["outcome"]] += 1
        if run["outcome"] != "completed":
            row[f"{run['outcome']}_reasons"][run["reason"]] += 1
        row["vehicle_ends"][run["vehicle_end"].split(" at ")[0]] += 1
    print(f"\n{'condition':18s} {'runs':>4s} {'completed':>9s} {'safe':>5s} {'flyaway':>7s}  safe ends: reason (count)")
    for condition, row in table.items():
        reasons = "; ".join(f"{reason} ({count})" for reason, count in row["safe_reasons"].most_common())
        print(f"{condition:18s} {row['runs']:4d} {row['completed']:9d} {row['safe']:5d} {row['flyaway']:7d}  "
              f"{reasons or '-'}")
        for key in ("safe_reasons", "flyaway_reasons", "vehicle_ends"):
            row[key] = dict(row[key])
    return table


if __name__ == "__main__":
    sys.exit(main())
