"""What one decision of each pilot costs on board: ``SearchPilot.decide`` (the search state, the observation, the
pilot's choice, the shield) on one core, for the shipped HRL-SAC artifact (the reference in the same run) and the
scripted searchers that fly with ``--pilot NAME``, at 1 km (SarSearch-v1's scenarios) and on the 2 km square.

Each pilot flies the first ``--scenarios`` val scenarios from home for up to ``--steps`` decisions, its velocity
commands flown exactly (1 s per decision); every ``decide`` call is timed. Prints the median, p99 and largest time
per decision and each median as a multiple of the artifact's, and writes them to benchmarks/results/pilot_cost.json.

Usage: python benchmarks/pilot_cost.py [--scenarios 5] [--steps 300]
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np
import torch
from common import ROOT, results_file, write_report

from autonomy.pilots import ScriptedPilot
from autonomy.policy import load_policy
from autonomy.search_pilot import SearchPilot
from missions.generator import TASK_V1, generate_scenario, scenario_seeds
from missions.mission import FlightSettings, Mission
from policies.cli.evaluate import read_generator_config

PILOTS = ("hrl-sac", "greedy_bayes", "lookahead_bayes")


def decision_times_ms(pilot_for, config, scenarios: int, steps: int) -> np.ndarray:
    """Every decision's wall time (ms) over the first ``scenarios`` val scenarios drawn from ``config``."""
    times = []
    for seed in scenario_seeds("val", scenarios):
        scenario = generate_scenario(seed, config)
        pilot = SearchPilot(Mission(scenario=scenario, flight=FlightSettings()), pilot_for(), seed)
        position = np.zeros(2)
        for _ in range(steps):
            started = time.perf_counter()
            decision = pilot.decide(position.copy())
            times.append(time.perf_counter() - started)
            if decision.end is not None:
                break
            position = position + np.array(decision.velocity_ne)
    return np.array(times) * 1000.0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", type=int, default=5)
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--out", default=results_file("pilot_cost.json"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    artifact = load_policy(f"{ROOT}/policies/pretrained/hrl-sac.pt")
    areas = {"1km": TASK_V1, "2km": read_generator_config(f"{ROOT}/docs/results/large-area.yaml")}
    report: dict = {"scenarios": args.scenarios, "steps": args.steps, "reference": "hrl-sac", "areas": {}}
    for area, config in areas.items():
        rows = {}
        for name in PILOTS:
            pilot_for = (lambda: artifact) if name == "hrl-sac" else (lambda name=name: ScriptedPilot(name))
            times = decision_times_ms(pilot_for, config, args.scenarios, args.steps)
            rows[name] = {"decisions": len(times), "median_ms": float(np.median(times)),
                          "p99_ms": float(np.percentile(times, 99)), "max_ms": float(times.max())}
        for name, row in rows.items():
            row["median_vs_reference"] = row["median_ms"] / rows["hrl-sac"]["median_ms"]
            print(f"{area} {name:16s} {row['decisions']:5d} decisions: median {row['median_ms']:6.2f} ms "
                  f"({row['median_vs_reference']:.2f}x the artifact's), p99 {row['p99_ms']:6.2f} ms, "
                  f"max {row['max_ms']:6.2f} ms")
        report["areas"][area] = rows
    write_report(args.out, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
