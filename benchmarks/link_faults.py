"""Mission outcomes under link faults, on both autopilot personalities: completed, ended safely (with the
reason), ditched or flyaway, over several seeds.

Each condition is flown as a lockstep mission replay (``simulation.mission_replay``) against the simulated PX4 or
ArduPilot Copter with the faults on the vehicle's end of the link, both directions, seeded by the run's seed; the
outcome is judged from the simulator's ground truth (``simulation.flight_outcome``). "Completed" means the search ran to
its own end and the vehicle landed and disarmed at home: a search that the runner resumed after the vehicle's link-loss
failsafe counts, one that the outage ended does not. Outages start 10 s into the search (the search start of each seed's
clean run). ArduPilot is flown twice for the outages: with its defaults (GUID_TIMEOUT stops it, the GCS failsafe off)
and with the GCS failsafe on (FS_GCS_ENABLE 1, the companion as SYSID_MYGCS: it returns after 5 s).

Usage: python benchmarks/link_faults.py [--seeds 10] [--max-steps 60] [--autopilot px4|ardupilot|both]
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from collections import Counter

import torch
from common import results_file, write_report

from autonomy.policy import load_policy
from missions.mission_file import load_mission
from simulation.mission_replay import airframe_for, replay_mission
from sitl_bridge.faults import parse_link_faults
from sitl_bridge.vehicle import VehicleConfig

LOSS_CONDITIONS = ("loss=0", "loss=0.1", "loss=0.3", "loss=0.3,burst=5")
OUTAGE_LENGTHS_S = (0.5, 2.0, 10.0)
OUTAGE_AFTER_SEARCH_START_S = 10.0


GCS_FAILSAFE = {"FS_GCS_ENABLE": 1, "SYSID_MYGCS": 1}  # ArduPilot: the companion (system 1) as its GCS


def conditions(search_start_s: float, autopilot: str) -> list[tuple[str, str, dict]]:
    """(label, spec, vehicle params) of every condition for one seed; outages are placed in that seed's search."""
    start = round(search_start_s + OUTAGE_AFTER_SEARCH_START_S, 2)
    outages = [(f"outage {length:g} s", f"outage={start:g}:{length:g}", {}) for length in OUTAGE_LENGTHS_S]
    if autopilot == "ardupilot":
        outages += [(f"{label} FS_GCS", spec, GCS_FAILSAFE) for label, spec, _ in outages if "0.5" not in label]
    return [(spec, spec, {}) for spec in LOSS_CONDITIONS] + outages


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default="policies/pretrained/hrl-sac.pt")
    parser.add_argument("--mission", default="missions/library/demo.yaml")
    parser.add_argument("--max-steps", type=int, default=60, help="decisions per search (shortens the mission)")
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--autopilot", choices=("px4", "ardupilot", "both"), default="both")
    parser.add_argument("--out", default=results_file("link_faults.json"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    mission = load_mission(args.mission)
    mission = dataclasses.replace(mission, flight=dataclasses.replace(mission.flight, max_steps=args.max_steps))
    policy = load_policy(args.policy)
    runs: list[dict] = []
    started = time.perf_counter()
    autopilots = ("px4", "ardupilot") if args.autopilot == "both" else (args.autopilot,)
    for autopilot in autopilots:
        for seed in range(args.seeds):
            def fly(spec: str, params: dict) -> dict:
                vehicle = VehicleConfig(home=mission.launch_point, seed=seed, airframe=airframe_for(mission),
                                        autopilot=autopilot, params=params)
                return replay_mission(mission, policy, seed=seed, video=False, vehicle_config=vehicle,
                                      link_faults=parse_link_faults(spec) if spec != "loss=0" else None)

            clean = fly("loss=0", {})
            search_start = next((t["time_s"] for t in clean["transitions"] if t["to"] == "SEARCH"), 20.0)
            for label, spec, params in conditions(search_start, autopilot):
                report = clean if spec == "loss=0" else fly(spec, params)
                outcome = report["outcome"]
                runs.append({"autopilot": autopilot, "condition": f"{autopilot} {label}", "spec": spec,
                             "vehicle_params": params, "seed": seed, "outcome": outcome["outcome"],
                             "reason": outcome["reason"], "vehicle_end": outcome["vehicle_end"],
                             "search_end": report["search_end"], "resumptions": report["resumptions"],
                             "flight_time_s": report["flight_time_s"],
                             "max_fence_excursion_m": outcome["max_fence_excursion_m"],
                             "longest_offboard_setpoint_gap_s": outcome["longest_offboard_setpoint_gap_s"]})
                print(f"  {autopilot:9s} seed {seed} {label:18s} {outcome['outcome']:9s} {outcome['reason']} "
                      f"[{outcome['vehicle_end']}] resumed {report['resumptions']}  "
                      f"({time.perf_counter() - started:.0f} s)", file=sys.stderr)
    table = summarise(runs)
    write_report(args.out, {"mission": args.mission, "max_steps": args.max_steps, "policy": args.policy,
                            "seeds": args.seeds, "autopilots": list(autopilots), "table": table, "runs": runs})
    return 0


def summarise(runs: list[dict]) -> dict[str, dict]:
    """Per condition: counts of each outcome and of each safe-end reason; printed as a table."""
    table: dict[str, dict] = {}
    for run in runs:
        row = table.setdefault(run["condition"], {"runs": 0, "completed": 0, "safe": 0, "ditched": 0, "flyaway": 0,
                                                  "resumed": 0, "safe_reasons": Counter(), "ditched_reasons": Counter(),
                                                  "flyaway_reasons": Counter(), "vehicle_ends": Counter()})
        row["runs"] += 1
        row[run["outcome"]] += 1
        row["resumed"] += run["resumptions"] > 0
        if run["outcome"] != "completed":
            row[f"{run['outcome']}_reasons"][run["reason"]] += 1
        row["vehicle_ends"][run["vehicle_end"].split(" at ")[0]] += 1
    print(f"\n{'condition':28s} {'runs':>4s} {'completed':>9s} {'resumed':>7s} {'safe':>5s} {'ditched':>7s} "
          f"{'flyaway':>7s}  other ends: reason (count)")
    for condition, row in table.items():
        reasons = "; ".join(f"{reason} ({count})" for key in ("safe_reasons", "ditched_reasons", "flyaway_reasons")
                            for reason, count in row[key].most_common())
        print(f"{condition:28s} {row['runs']:4d} {row['completed']:9d} {row['resumed']:7d} {row['safe']:5d} "
              f"{row['ditched']:7d} {row['flyaway']:7d}  {reasons or '-'}")
        for key in ("safe_reasons", "ditched_reasons", "flyaway_reasons", "vehicle_ends"):
            row[key] = dict(row[key])
    return table


if __name__ == "__main__":
    sys.exit(main())
