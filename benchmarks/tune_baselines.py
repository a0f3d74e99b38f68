"""Tuning SarSearch-v1's scripted searchers on the val split (never on test): coordinate descent over their knobs.

For each searcher, starting from ``ScriptedSettings()``, every knob in turn is set to each of its candidate values
(the others held) and kept at the best; two passes. Best = the highest success rate on the first --episodes val
scenarios among settings that run dry in at most --max-ran-dry of them (a crew keeps its reserve). Every
evaluation is written to the JSON report, the chosen settings last; ``missions.searchers.TUNED`` is set from it.

Usage: python benchmarks/tune_baselines.py [--episodes 500] [--only greedy_bayes] [--out FILE]
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time

from common import results_file, write_report

from missions.searchers import ScriptedSettings
from policies.evaluation.baselines import run_baseline

KNOBS = {
    "coverage_factor": (0.6, 0.8, 1.0, 1.3, 1.7, 2.2, 3.0),
    "bound_sigmas": (1.0, 1.5, 2.0, 2.5, 3.0, 4.0),
    "travel_time_s": (5.0, 15.0, 30.0, 60.0, 150.0, 400.0),
    "investigate_plausibility": (0.0, 0.02, 0.1, 0.3),
    "close_look_zoom": (0.0, 0.3, 0.5, 0.8, 1.0),
    "reserve_s": (0.0, 20.0, 60.0),
}
USES = {"expanding_square": ("coverage_factor", "bound_sigmas"), "parallel_track": ("coverage_factor", "bound_sigmas"),
        "greedy_bayes": ("travel_time_s",)}
SHARED = ("investigate_plausibility", "close_look_zoom", "reserve_s")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=500)
    parser.add_argument("--passes", type=int, default=2)
    parser.add_argument("--max-ran-dry", type=float, default=0.01)
    parser.add_argument("--only", choices=sorted(USES), default=None)
    parser.add_argument("--out", default=results_file("tune_baselines.json"))
    args = parser.parse_args()
    report = {"split": "val", "episodes": args.episodes, "max_ran_dry": args.max_ran_dry, "searchers": {}}
    for name in [args.only] if args.only else USES:
        cache: dict[ScriptedSettings, dict] = {}

        def score(settings: ScriptedSettings) -> tuple[float, float]:
            if settings not in cache:
                started = time.perf_counter()
                result = run_baseline(name, "val", args.episodes, settings=settings)
                cache[settings] = {"settings": dataclasses.asdict(settings), "success_rate": result["success_rate"],
                                   "ran_dry_rate": result["ran_dry_rate"], "returned_rate": result["returned_rate"],
                                   "collision_rate": result["collision_rate"], "found_by": result["found_by"]}
                print(f"{name:17s} {_describe(settings, name)}  success {result['success_rate']:.3f}  ran dry "
                      f"{result['ran_dry_rate']:.3f}  ({time.perf_counter() - started:.0f} s)", flush=True)
            entry = cache[settings]
            safe = entry["ran_dry_rate"] <= args.max_ran_dry
            return (entry["success_rate"] if safe else -1.0, -entry["ran_dry_rate"])

        best = ScriptedSettings()
        for _ in range(args.passes):
            for knob in USES[name] + SHARED:
                candidates = [dataclasses.replace(best, **{knob: value}) for value in KNOBS[knob]]
                best = max(candidates, key=score)
        report["searchers"][name] = {"evaluations": list(cache.values()), "chosen": dataclasses.asdict(best),
                                     "chosen_result": cache[best]}
        print(f"{name}: chosen {_describe(best, name)} -> success {cache[best]['success_rate']:.3f}", flush=True)
        write_report(args.out, report)
    return 0


def _describe(settings: ScriptedSettings, name: str) -> str:
    return " ".join(f"{knob}={getattr(settings, knob):g}" for knob in USES[name] + SHARED)


if __name__ == "__main__":
    sys.exit(main())
