"""Summarise sweeps' evaluations on a split (val: 500 scenarios, test: 1,000): per seed the success under the
environment's and the mission runner's rules and the share that ran dry; for HRL-SAC also the sub-goal reachability,
TrackObject at every decision and the scenarios only one of the two won; the means over seeds with their t 95 %
intervals.

Each run needs ``hrlsac evaluate RUN --split SPLIT --episodes N`` with and without ``--flight-rules`` (the default
file names), and HRL-SAC runs also ``--constant-goal TrackObject`` (``RUN/eval_SPLIT_goal-TrackObject.json``; on
val the earlier ``--out RUN/eval_val_track.json`` is read too). The learned - TrackObject difference is paired:
the same scenarios and detection draws.

With ``--scenarios NAME`` the evaluations of another scenario distribution are read (the name ``hrlsac evaluate
--generator FILE`` gave them, e.g. ``generator-large-area`` for the 2 km square: ``RUN/eval_test_NAME.json`` ...).

Usage: python docs/results/val_summary.py SWEEP_DIR [SWEEP_DIR ...] [--split val|test] [--scenarios NAME]
                                          [--out FILE.json]
"""
from __future__ import annotations

import argparse
import json
import pathlib

from autonomy.recorder import write_json_atomic
from policies.evaluation.stats import t_interval


def mean_t95(values: list[float]) -> list[float]:
    """[mean, low, high]: the t 95 % interval over seeds (the mean alone for one), as `hrlsac compare` computes it."""
    mean, _, interval = t_interval(values)
    low, high = interval or (mean, mean)
    return [round(mean, 4), round(low, 4), round(high, 4)]


def run_row(run: pathlib.Path, split: str, scenarios: str = "") -> dict:
    prefix = f"eval_{split}_{scenarios}" if scenarios else f"eval_{split}"
    env = json.loads((run / f"{prefix}.json").read_text())
    flight = json.loads((run / f"{prefix}_flight.json").read_text())
    row = {"success": env["success_rate"], "ran_dry": env["ran_dry_rate"],
           "success_runner_rules": flight["success_rate"]}
    track_files = [run / f"{prefix}_goal-TrackObject.json", run / f"{prefix}_track.json"]
    track_file = next((f for f in track_files if f.exists()), None)
    if track_file is not None:
        track = json.loads(track_file.read_text())
        learned, always = env["per_episode"]["success"], track["per_episode"]["success"]
        row.update(subgoal_reachability=round(env["subgoal_reachability"], 4),
                   success_always_track_object=track["success_rate"],
                   learned_only=sum(a and not b for a, b in zip(learned, always)),
                   track_object_only=sum(b and not a for a, b in zip(learned, always)))
    return row


def sweep_summary(sweep: pathlib.Path, split: str, scenarios: str = "") -> dict:
    prefix = f"eval_{split}_{scenarios}" if scenarios else f"eval_{split}"
    runs = sorted(p for p in sweep.iterdir() if (p / f"{prefix}.json").exists())
    seeds = {json.loads((run / "config.json").read_text())["seed"]: run_row(run, split, scenarios) for run in runs}
    rows = list(seeds.values())
    summary = {"seeds": {str(seed): row for seed, row in sorted(seeds.items())},
               "success_mean_t95": mean_t95([r["success"] for r in rows]),
               "success_runner_rules_mean_t95": mean_t95([r["success_runner_rules"] for r in rows])}
    if rows and all("success_always_track_object" in r for r in rows):
        summary["success_always_track_object_mean_t95"] = mean_t95([r["success_always_track_object"] for r in rows])
        summary["learned_minus_track_object_mean_t95"] = mean_t95(
            [r["success"] - r["success_always_track_object"] for r in rows])
    return summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sweeps", nargs="+", type=pathlib.Path, help="sweep folders (hrlsac sweep --out)")
    parser.add_argument("--split", choices=["val", "test"], default="val", help="the split evaluated (default val)")
    parser.add_argument("--scenarios", default="",
                        help="the evaluations of another distribution, by the name in their files (generator-NAME)")
    parser.add_argument("--out", type=pathlib.Path, help="also write the summary to this JSON file")
    args = parser.parse_args()
    summary = {"split": args.split, "scenarios": args.scenarios or "the split's own",
               **{sweep.name: sweep_summary(sweep, args.split, args.scenarios) for sweep in args.sweeps}}
    print(json.dumps(summary, indent=2))
    if args.out:
        write_json_atomic(args.out, summary)


if __name__ == "__main__":
    main()
