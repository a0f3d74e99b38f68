"""What limits a trained run's test success: its deterministic policy against variants of how it acts.

Variants, on the same first --episodes scenarios of the split (scenario i with episode seed i):
  * deterministic: the evaluation's policy (tanh of the mean, both levels);
  * sampled_low_level: the low level's actions sampled from its squashed Gaussian (seeded generator);
  * intensity_forced_on: deterministic, but search intensity always 1 (the sensor always on);
  * sampled_meta (HRL-SAC only): deterministic low level, goals sampled from the meta-controller's softmax.

A large gain from sampling or from forcing the sensor on says the learned deterministic action, not the
policy's knowledge of where to fly, is what fails (docs/results/README.md).

Usage: python benchmarks/action_ablation.py RUN [--episodes 300] [--split test] [--out FILE]
"""
from __future__ import annotations

import argparse
import sys

import numpy as np
import torch

from policies.checkpoint_policy import CheckpointPolicy
from policies.evaluation import episode_batch, run_episodes, summarise
from policies.parallel_evaluation import padded

from common import write_report

SEARCH_INTENSITY = 2  # action component (docs/environment.md)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", help="run folder written by hrlsac train")
    parser.add_argument("--episodes", type=int, default=300)
    parser.add_argument("--split", default="test", choices=["train", "val", "test"])
    parser.add_argument("--out", default="benchmarks/results/action_ablation.json")
    args = parser.parse_args()
    torch.set_num_threads(1)
    policy = CheckpointPolicy.load(args.run)
    normalise = policy.normalizer.normalize

    def deterministic(obs: np.ndarray) -> np.ndarray:
        return policy.low.act(normalise(obs), deterministic=True)

    def sampled(obs: np.ndarray) -> np.ndarray:
        return policy.low.act(normalise(obs), deterministic=False)

    def sensor_on(obs: np.ndarray) -> np.ndarray:
        actions = deterministic(obs).copy()
        actions[:, SEARCH_INTENSITY] = 1.0
        return actions

    def goals(sample: bool):
        if not policy.hierarchical:
            return None
        return padded(lambda meta_obs: policy.meta.act(normalise(meta_obs), deterministic=not sample))

    variants = {"deterministic": (deterministic, goals(False)), "sampled_low_level": (sampled, goals(False)),
                "intensity_forced_on": (sensor_on, goals(False))}
    if policy.hierarchical:
        variants["sampled_meta"] = (deterministic, goals(True))
    results = {}
    for name, (act, choose_goals) in variants.items():
        core = episode_batch(args.split, args.episodes, policy.config.flight, goal_conditioned=policy.hierarchical)
        # padded as in hrlsac evaluate, so the deterministic variant is exactly the evaluation's policy
        metrics = summarise(run_episodes(core, lambda batch, act=padded(act): act(batch.obs), choose_goals))
        results[name] = {key: metrics[key] for key in ("success_rate", "success_ci95", "coverage_mean",
                                                       "detection_rate", "out_of_bounds_rate", "collision_rate")}
        low, high = metrics["success_ci95"]
        print(f"  {name:20s} success {metrics['success_rate']:6.1%} [{low:.1%}, {high:.1%}]  coverage "
              f"{metrics['coverage_mean']:.1%}  detection {metrics['detection_rate']:.1%}")
    write_report(args.out, {"run": args.run, "algo": policy.config.algo, "trained_steps": policy.step,
                            "split": args.split, "episodes": args.episodes, "variants": results})
    return 0


if __name__ == "__main__":
    sys.exit(main())
