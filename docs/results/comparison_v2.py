"""comparison-v2's table: the re-tuned flat SAC runs beside comparison-v1's HRL-SAC runs, from their eval files.

HRL-SAC and the scripted searchers did not change between v1 and v2 (the same runs, code and test scenarios), so
their rows are read from comparison-v1's evaluations and reports; only the flat SAC rows are new. For each of the
four settings of comparison-v1 (the 1 km task and the 2 km square, the environment's and the mission runner's
rules) this prints HRL-SAC's and both flat SAC's rows: success mean, std and t 95 % interval over the 5 runs, IQM
with its stratified-bootstrap interval over runs x condition strata, ran dry, and the verdicts of HRL-SAC against
each flat SAC (``policies.reports.groups.verdicts_against``, the test of ``hrlsac compare``), and writes it all
to docs/results/comparison-v2/summary.json.

Usage (from the project root): python docs/results/comparison_v2.py V1_RUNS V2_RUNS
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from policies.cli.evaluate import read_generator_config
from policies.evaluation.aggregate import aggregate, strata_of
from policies.evaluation.episodes import episode_batch
from policies.evaluation.stats import group_stats
from policies.reports.groups import verdicts_against
from policies.reports.runs import common_flight, load_runs

SETTINGS = {"1 km, environment's rules": "eval_test.json", "1 km, runner's rules": "eval_test_flight.json",
            "2 km, environment's rules": "eval_test_generator-large-area.json",
            "2 km, runner's rules": "eval_test_generator-large-area_flight.json"}
LARGE = Path(__file__).with_name("large-area.yaml")
EPISODES = 1000


def row(label: str, folders: list[Path], name: str, strata: np.ndarray, count: int) -> dict:
    metrics = [json.loads((folder / name).read_text()) for folder in folders]
    successes = [np.asarray(m["per_episode"]["success"], dtype=bool) for m in metrics]
    return {"label": label, **group_stats(metrics), "aggregate": aggregate(successes, strata, count),
            "ran_dry_rate": float(np.mean([m["ran_dry_rate"] for m in metrics]))}


def main(v1: Path, v2: Path) -> int:
    hrl = [v1 / f"hrl-sac-default-seed{seed}" for seed in range(5)]
    flat_v1 = [v1 / f"sac-default-seed{seed}" for seed in range(5)]
    flat_v2 = [v2 / f"sac-default-seed{seed}" for seed in range(5)]
    flight = common_flight(load_runs(hrl + flat_v2, "test"))
    summary = {"command": f"python docs/results/comparison_v2.py {v1} {v2}", "settings": {}}
    for setting, name in SETTINGS.items():
        environment = {"generator": read_generator_config(str(LARGE))} if "large" in name else {}
        scenarios = episode_batch("test", EPISODES, flight, goal_conditioned=False, task="SarSearch-v1",
                                  **environment).scenarios
        strata, names = strata_of(scenarios)
        rows = [row("HRL-SAC", hrl, name, strata, len(names)),
                row("flat SAC v1 (fA: 1-step)", flat_v1, name, strata, len(names)),
                row("flat SAC v2 (fC: n_step 3)", flat_v2, name, strata, len(names))]
        summary["settings"][setting] = {"rows": rows, "verdicts": verdicts_against(rows[0], rows[1:])}
        print(f"\n{setting} (1,000 test scenarios, 5 runs each)")
        print("| method | success | t 95 % | IQM [95 %] | ran dry |")
        print("|---|---|---|---|---|")
        for r in rows:
            t95, agg = r["success_t95"], r["aggregate"]
            print(f"| {r['label']} | {100 * r['success_mean']:.1f} ± {100 * r['success_std']:.1f} % | "
                  f"[{100 * t95[0]:.1f}, {100 * t95[1]:.1f}] | {100 * agg['iqm']:.1f} % "
                  f"[{100 * agg['iqm_ci95'][0]:.1f}, {100 * agg['iqm_ci95'][1]:.1f}] | {100 * r['ran_dry_rate']:.1f} % |")
        for verdict in summary["settings"][setting]["verdicts"]:
            print(f"HRL-SAC above {verdict['against']}: seeds' t intervals apart "
                  f"{verdict['above_non_overlapping_seeds']}, IQM intervals apart {verdict['above_non_overlapping_iqm']}")
    out = Path(__file__).with_name("comparison-v2") / "summary.json"
    out.parent.mkdir(exist_ok=True)
    tmp = out.with_suffix(".tmp")
    tmp.write_text(json.dumps(summary, indent=1))
    tmp.replace(out)
    print(f"\nwritten {out}")
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__.strip().splitlines()[-1])
    sys.exit(main(Path(sys.argv[1]), Path(sys.argv[2])))
