"""Why searches fail: each method's failures split by whether the victim was ever sighted, and by how they ended.

A failed SarSearch-v1 episode either never had the victim in view (the search looked in the wrong places, or
looked where it was and the detection draw missed it) or saw it and still did not reach a confirmed victim
(the close look came too late, the endurance ran out, the search went home). Learned methods are read from
their evaluation files (``hrlsac evaluate`` writes every episode's success, end and first victim sighting);
scripted searchers are flown here on the same scenarios (scenario i, episode seed i, detection stream 0).

Usage: python benchmarks/failure_modes.py [--eval FILE ...] [--scripted greedy_bayes ...] [--split test]
       [--episodes 1000] [--generator docs/results/large-area.yaml] [--out ...]
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch
from common import results_file, write_report

from missions.generator import SPLITS
from missions.mission import FlightSettings
from policies.evaluation.baselines import run_baseline


def failure_modes(per_episode: dict) -> dict[str, float]:
    """Shares of all episodes: success, and failure by (victim sighted or not) x (ran dry or another end)."""
    success = np.asarray(per_episode["success"], dtype=bool)
    ran_dry = np.asarray(per_episode["ran_dry"], dtype=bool)
    sighted = np.asarray(per_episode["first_detection"]) >= 0
    failed = ~success
    return {"episodes": int(success.size), "success": float(success.mean()),
            "failed_never_sighted": float((failed & ~sighted).mean()),
            "failed_never_sighted_ran_dry": float((failed & ~sighted & ran_dry).mean()),
            "failed_sighted": float((failed & sighted).mean()),
            "failed_sighted_ran_dry": float((failed & sighted & ran_dry).mean())}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--eval", nargs="*", default=[], help="evaluation files of hrlsac evaluate (eval_*.json)")
    parser.add_argument("--scripted", nargs="*", default=[],
                        help="scripted searchers to fly (missions.searchers)")
    parser.add_argument("--split", default="val", choices=SPLITS)
    parser.add_argument("--episodes", type=int, default=500)
    parser.add_argument("--generator", default=None, help="generator config file (as hrlsac evaluate --generator)")
    parser.add_argument("--out", default=results_file("failure_modes.json"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    environment = {}
    if args.generator is not None:
        from policies.cli.evaluate import read_generator_config

        environment["generator"] = read_generator_config(args.generator)
    rows = []
    for path in args.eval:
        try:
            metrics = json.loads(open(path).read())
            rows.append({"method": "/".join(Path(path).parts[-2:]), "file": path,
                         **failure_modes(metrics["per_episode"])})
        except (OSError, ValueError, KeyError) as exc:
            raise SystemExit(f"failure_modes.py: error: {path}: not an evaluation file with per-episode records "
                             f"({exc.__class__.__name__}: {exc})") from None
    for name in args.scripted:
        metrics = run_baseline(name, args.split, args.episodes, FlightSettings(), **environment)
        rows.append({"method": name, **failure_modes(metrics["per_episode"])})
    width = max([len(row["method"]) for row in rows] + [6])
    print(f"{'method':{width}s} {'success':>8s} {'never sighted (ran dry)':>24s} {'sighted, failed (ran dry)':>26s}")
    for row in rows:
        print(f"{row['method']:{width}s} {row['success']:8.1%} "
              f"{row['failed_never_sighted']:12.1%} ({row['failed_never_sighted_ran_dry']:5.1%})    "
              f"{row['failed_sighted']:13.1%} ({row['failed_sighted_ran_dry']:5.1%})", flush=True)
    write_report(args.out, {"split": args.split, "episodes": args.episodes, "generator": args.generator,
                            "methods": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
