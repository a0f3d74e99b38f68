"""Difficulty calibration: the scripted searchers on a split (SarSearch-v1's, with their settings tuned on val;
``--task SarSearch-v0`` for the paper's task and its baselines).

Prints, per baseline, success rate (Wilson 95 % interval), collision / out-of-bounds / ran-dry / returned rates,
coverage and the time-to-find distribution (steps to first detection of the victim and to success), and writes
them to benchmarks/results/baselines.json. Targets: random <= 10 % success, the best scripted searcher >= 60 %.
``--only NAME[,NAME]`` flies only those searchers, ``--streams N`` each over N detection streams (the same
scenarios, other draws; ``hrlsac compare``'s scripted rows use 5) with the streams' mean and t 95 % interval, and
``--generator FILE`` draws the scenarios from a generator config file (e.g. docs/results/large-area.yaml, the 2 km
square). With several
searchers each is also compared with the first, paired on the same scenarios and streams, with a 95 % interval from
a bootstrap over the scenarios (``policies.evaluation.aggregate.paired_scenario_bootstrap``).

Usage: python benchmarks/baselines.py [--episodes 500] [--split test] [--task SarSearch-v1] [--only NAMES]
                                      [--streams 1] [--generator FILE]
"""
from __future__ import annotations

import argparse
import sys
import time

from common import results_file, write_report

from missions.generator import SPLITS
from missions.searchers import SEARCHERS
from policies.cli.evaluate import read_generator_config
from policies.env.baselines_v0 import BASELINES_V0
from policies.evaluation.aggregate import paired_scenario_bootstrap
from policies.evaluation.baselines import run_baseline
from policies.evaluation.stats import t_interval


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=500)
    parser.add_argument("--split", default="test", choices=SPLITS)
    parser.add_argument("--task", default="SarSearch-v1", choices=["SarSearch-v0", "SarSearch-v1"])
    parser.add_argument("--only", default=None, help="fly only these searchers (comma-separated names)")
    parser.add_argument("--streams", type=int, default=1, help="detection streams per searcher (default 1)")
    parser.add_argument("--generator", default=None, help="generator config file (YAML) instead of the task's")
    parser.add_argument("--out", default=results_file("baselines.json"))
    args = parser.parse_args()
    names = list(SEARCHERS if args.task == "SarSearch-v1" else BASELINES_V0)
    chosen = names if args.only is None else [name.strip() for name in args.only.split(",")]
    unknown = [name for name in chosen if name not in names]
    if unknown:
        parser.error(f"--only: no scripted searcher {unknown[0]!r} on {args.task}; choose from {', '.join(names)}")
    if args.streams < 1:
        parser.error(f"--streams must be >= 1, got {args.streams}")
    try:
        environment = {"generator": read_generator_config(args.generator)} if args.generator else {}
    except ValueError as exc:
        parser.error(str(exc))
    results, streams, successes = [], {}, {}
    for name in chosen:
        for stream in range(args.streams):
            start = time.perf_counter()
            result = run_baseline(name, args.split, args.episodes, task=args.task, stream=stream, **environment)
            result["wall_s"] = time.perf_counter() - start
            results.append(result)
            streams.setdefault(name, []).append(result["success_rate"])
            successes.setdefault(name, []).append(result["per_episode"]["success"])
            print_result(name if args.streams == 1 else f"{name}, stream {stream}", result)
    summary = {}
    for name, rates in streams.items():
        if len(rates) > 1:
            mean, _, t95 = t_interval(rates)
            summary[name] = {"per_stream": rates, "mean": mean, "t95": t95}
    first = chosen[0]
    for name in chosen[1:]:  # each against the first, paired on the same scenarios and streams
        mean, low, high = paired_scenario_bootstrap(successes[name], successes[first])
        summary.setdefault(name, {})[f"minus_{first}"] = {"mean": mean, "scenario_bootstrap95": [low, high]}
    for name, row in summary.items():
        if "per_stream" in row:
            print(f"{name}: mean over {len(row['per_stream'])} streams {row['mean']:.1%} "
                  f"[{row['t95'][0]:.1%}, {row['t95'][1]:.1%}]")
        if f"minus_{first}" in row:
            paired = row[f"minus_{first}"]
            print(f"{name} - {first}: {paired['mean']:+.1%} (scenario bootstrap 95 % "
                  f"[{paired['scenario_bootstrap95'][0]:+.1%}, {paired['scenario_bootstrap95'][1]:+.1%}])")
    write_report(args.out, {"split": args.split, "episodes": args.episodes, "generator_file": args.generator,
                            "streams": summary, "results": results})
    return 0


def print_result(name: str, result: dict) -> None:
    """One line per run: success (Wilson 95 %), the other ends, coverage, times to detection and success."""
    low, high = result["success_ci95"]
    ttf = result["time_to_first_detection"]
    tts = result["steps_to_success"]
    print(f"{name:17s} success {result['success_rate']:6.1%} [{low:.1%}, {high:.1%}]  "
          f"collision {result['collision_rate']:5.1%}  out {result['out_of_bounds_rate']:5.1%}  "
          f"ran dry {result['ran_dry_rate']:5.1%}  returned {result['returned_rate']:5.1%}  "
          f"coverage {result['coverage_mean']:5.1%}  first detection p25/p50/p75 "
          f"{_fmt(ttf['p25'])}/{_fmt(ttf['p50'])}/{_fmt(ttf['p75'])}  success at p25/p50/p75 "
          f"{_fmt(tts['p25'])}/{_fmt(tts['p50'])}/{_fmt(tts['p75'])}  ({result['wall_s']:.1f} s)", flush=True)


def _fmt(value) -> str:
    return "-" if value is None else f"{value:.0f}"


if __name__ == "__main__":
    sys.exit(main())
