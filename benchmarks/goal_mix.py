"""Which goals a trained HRL-SAC run's deterministic meta-controller chooses, and how its episodes end.

Flies the run's deterministic policy (both levels) on the first --episodes scenarios of the split (scenario i,
episode seed i), counting the goal of every decision; prints the share of each goal and the success, ran-dry and
returned rates, and writes them to benchmarks/results/goal_mix.json. It is how a meta-controller's collapse onto
one goal (ReturnToBase, TrackObject) is seen (docs/training.md, "SarSearch-v1 options").

Usage: python benchmarks/goal_mix.py RUN [RUN ...] [--episodes 200] [--split val]
"""
from __future__ import annotations

import argparse
import collections
import sys

import torch
from common import results_file, write_report

from missions.generator import SPLITS
from missions.goals import GOAL_NAMES
from policies.checkpoint import CheckpointPolicy
from policies.evaluation.episodes import episode_batch, run_episodes, summarise


def goal_mix(run: str, split: str, episodes: int) -> dict:
    policy = CheckpointPolicy.load(run)
    if not policy.hierarchical:
        raise SystemExit(f"goal_mix.py: error: {run} is a flat SAC run (no meta-controller)")
    config = policy.config
    core = episode_batch(split, episodes, config.flight, goal_conditioned=True, task=config.task,
                         action_frame=config.action_frame)
    counts: collections.Counter = collections.Counter()

    def choose(meta_obs):
        goals = policy.choose_goals(meta_obs)
        counts.update(GOAL_NAMES[g] for g in goals)
        return goals

    metrics = summarise(run_episodes(core, lambda batch: policy.act(batch.obs), choose))
    total = sum(counts.values())
    return {"run": run, "trained_steps": policy.step, "split": split, "episodes": episodes,
            "goal_share": {name: counts[name] / total for name in GOAL_NAMES},
            **{key: metrics[key] for key in ("success_rate", "ran_dry_rate", "returned_rate")}}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", help="run folders (or checkpoint files) of hrlsac train --algo hrl-sac")
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--split", default="val", choices=SPLITS)
    parser.add_argument("--out", default=results_file("goal_mix.json"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    results = []
    for run in args.runs:
        result = goal_mix(run, args.split, args.episodes)
        shares = "  ".join(f"{name} {share:.0%}" for name, share in result["goal_share"].items())
        print(f"{run} (step {result['trained_steps']:,}): {shares}  success {result['success_rate']:.1%}  ran dry "
              f"{result['ran_dry_rate']:.1%}  returned {result['returned_rate']:.1%}", flush=True)
        results.append(result)
    write_report(args.out, {"runs": results})
    return 0


if __name__ == "__main__":
    sys.exit(main())
