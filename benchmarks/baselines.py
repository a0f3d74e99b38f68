"""Difficulty calibration: the scripted searchers on a split (SarSearch-v1's, with their settings tuned on val;
``--task SarSearch-v0`` for the paper's task and its baselines).

Prints, per baseline, success rate (Wilson 95 % interval), collision / out-of-bounds / ran-dry / returned rates,
coverage and the time-to-find distribution (steps to first detection of the victim and to success), and writes
them to benchmarks/results/baselines.json. Targets: random <= 10 % success, the best scripted searcher >= 60 %.

Usage: python benchmarks/baselines.py [--episodes 500] [--split test] [--task SarSearch-v1]
"""
from __future__ import annotations

import argparse
import sys
import time

from common import results_file, write_report

from policies.env.baselines import BASELINES
from policies.env.baselines_v0 import BASELINES_V0
from policies.evaluation.baselines import run_baseline


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=500)
    parser.add_argument("--split", default="test", choices=["train", "val", "test"])
    parser.add_argument("--task", default="SarSearch-v1", choices=["SarSearch-v0", "SarSearch-v1"])
    parser.add_argument("--out", default=results_file("baselines.json"))
    args = parser.parse_args()
    results = []
    for name in BASELINES if args.task == "SarSearch-v1" else BASELINES_V0:
        start = time.perf_counter()
        result = run_baseline(name, args.split, args.episodes, task=args.task)
        result["wall_s"] = time.perf_counter() - start
        results.append(result)
        low, high = result["success_ci95"]
        ttf = result["time_to_first_detection"]
        tts = result["steps_to_success"]
        print(f"{name:17s} success {result['success_rate']:6.1%} [{low:.1%}, {high:.1%}]  "
              f"collision {result['collision_rate']:5.1%}  out {result['out_of_bounds_rate']:5.1%}  "
              f"ran dry {result['ran_dry_rate']:5.1%}  returned {result['returned_rate']:5.1%}  "
              f"coverage {result['coverage_mean']:5.1%}  first detection p25/p50/p75 "
              f"{_fmt(ttf['p25'])}/{_fmt(ttf['p50'])}/{_fmt(ttf['p75'])}  success at p25/p50/p75 "
              f"{_fmt(tts['p25'])}/{_fmt(tts['p50'])}/{_fmt(tts['p75'])}  ({result['wall_s']:.1f} s)", flush=True)
    write_report(args.out, {"results": results})
    return 0


def _fmt(value) -> str:
    return "-" if value is None else f"{value:.0f}"


if __name__ == "__main__":
    sys.exit(main())
