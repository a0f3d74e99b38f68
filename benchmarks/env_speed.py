"""Environment speed: steps per second, single and vectorised, on one core, for both task versions.

Figures (median of --repeats runs, random actions, auto-resets included), for SarSearch-v0 (the paper's task) and
SarSearch-v1 (the default, whose step also advances the search belief):
  * single_raw_steps_per_s_v0 / _v1: SarSearchEnv(task=...).step, no gymnasium wrappers
  * single_make_steps_per_s: gymnasium.make("SarSearch-v0") with gymnasium's checker/order wrappers
  * vector_steps_per_s_v0 / _v1: SarSearchVectorEnv with --num-envs environments (scenario pool warmed first)
  * reference_pendulum_steps_per_s: gymnasium's Pendulum-v1 in the same run, for comparing noisy runs
Targets (set for SarSearch-v0's step): >= 10,000 single and >= 200,000 vectorised steps/s; the v1 figures are
printed beside them.

Usage: python benchmarks/env_speed.py [--steps 20000] [--num-envs 1024] [--repeats 5]
"""
from __future__ import annotations

import argparse
import sys
import time

import gymnasium
import numpy as np
from common import results_file, summarise, write_report

import policies  # noqa: F401  (registers SarSearch-v0)
from policies.env.core import SarSearchConfig
from policies.env.gym_env import SarSearchEnv
from policies.env.vector import SarSearchVectorEnv


def single_steps_per_s(env, steps: int) -> float:
    rng = np.random.default_rng(0)
    actions = rng.uniform(env.action_space.low, env.action_space.high, size=(steps, 4)).astype(np.float32)
    env.reset(seed=0)
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - start)


def vector_steps_per_s(num_envs: int, steps: int, task: str) -> float:
    env = SarSearchVectorEnv(num_envs, SarSearchConfig(pool_size=2_000, task=task))
    rng = np.random.default_rng(0)
    actions = rng.uniform([-1, -1, 0, 0], 1, size=(16, num_envs, 4)).astype(np.float32)
    env.reset(seed=0)
    for t in range(300):  # warm the scenario pool (each scenario is generated once)
        env.step(actions[t % 16])
    batches = max(1, steps // num_envs)
    start = time.perf_counter()
    for t in range(batches):
        env.step(actions[t % 16])
    return batches * num_envs / (time.perf_counter() - start)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--num-envs", type=int, default=1024)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", default=results_file("env_speed.json"))
    args = parser.parse_args()
    runs: dict[str, list[float]] = {name: [] for name in (
        "single_raw_steps_per_s_v0", "single_raw_steps_per_s_v1", "single_make_steps_per_s", "vector_steps_per_s_v0",
        "vector_steps_per_s_v1", "reference_pendulum_steps_per_s")}
    for repeat in range(args.repeats):
        runs["reference_pendulum_steps_per_s"].append(single_steps_per_s(gymnasium.make("Pendulum-v1"), args.steps))
        for version in ("v0", "v1"):
            task = f"SarSearch-{version}"
            runs[f"single_raw_steps_per_s_{version}"].append(single_steps_per_s(SarSearchEnv(task=task), args.steps))
            runs[f"vector_steps_per_s_{version}"].append(vector_steps_per_s(args.num_envs, args.steps * 20, task))
        runs["single_make_steps_per_s"].append(single_steps_per_s(gymnasium.make("SarSearch-v0"), args.steps))
        print(f"run {repeat + 1}/{args.repeats}: " + ", ".join(f"{k} {v[-1]:,.0f}" for k, v in runs.items()),
              flush=True)
    medians = summarise(runs, f"medians over {args.repeats} runs (one core, {args.num_envs} vectorised environments):")
    for name, target in (("single_raw_steps_per_s_v0", 10_000), ("vector_steps_per_s_v0", 200_000)):
        verdict = "meets" if medians[name] >= target else "MISSES"
        print(f"{name}: {verdict} the {target:,} target")
    write_report(args.out, {"num_envs": args.num_envs, "repeats": args.repeats, "medians": medians, "runs": runs})
    return 0


if __name__ == "__main__":
    sys.exit(main())
