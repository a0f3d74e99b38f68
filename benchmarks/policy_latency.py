"""Policy latency per control step at batch 1 on one thread: eager, TorchScript and torch.export, beside the FLOP
lower bound of each network, plus artifact sizes.

For each preset (untrained HRL-SAC agents built from ``TrainConfig.from_preset``; or the policy of --checkpoint) the
same policy runs four ways, each through the call a runner makes (numpy observation in, numpy out):

  * eager:            policies.checkpoint.CheckpointPolicy (numpy normaliser + SAC.act / DiscreteSAC.act)
  * torchscript:      autonomy.policy.load_policy of the TorchScript artifact (float32, the default export)
  * torch-export:     autonomy.policy.load_policy of the torch.export artifact (ExportedProgram.module())
  * torchscript-int8: the TorchScript artifact exported with precision "int8" (the low-level actor's hidden layers
                      with int8 weights and bfloat16 activations; goals exact, actions within the parity tolerance of
                      docs/export.md, "Precision")

A combined step is select_goal(meta observation) + act(observation), the work of a goal-decision step; act alone is
every other step. Inputs cycle through observations recorded in the environment. The three take turns in blocks
(--blocks) so that a change of machine load hits them alike. Figures: p50 and p99 of wall-clock time per call (and
of this thread's CPU time, less sensitive to other processes on a shared machine), in microseconds.

Reference, timed in the same blocks on the same thread: four bare 512 x 512 float32 ``F.linear`` calls at batch 1
(about the paper actor's matrix products, nothing else), which says how much of the target the machine itself
leaves.

Lower bound: the multiply-adds of the networks' Linear layers (2 FLOP each) at the peak FLOP rate of one thread,
measured in the same run as the best of several 1024 x 1024 float32 matmuls. Target: combined-step p99 <= 250 us at
the paper preset.

Usage: python benchmarks/policy_latency.py [--steps 3000] [--blocks 6] [--presets default,paper] [--checkpoint RUN]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from common import results_file, write_report  # first: it puts this checkout on sys.path

from autonomy.observation import META_OBS_DIM
from autonomy.policy import load_policy
from policies.checkpoint import CheckpointPolicy
from policies.config import TrainConfig
from policies.export.artifact import artifact_bytes, build_manifest
from policies.export.module import policy_module
from policies.export.parity import record_observations

ARTIFACTS = {"torchscript": ("torchscript", "float32"), "torch-export": ("torch-export", "float32"),
             "torchscript-int8": ("torchscript", "int8")}
"""Runner name -> (artifact format, precision)."""
RUNNERS = ("eager",) + tuple(ARTIFACTS)
CALLS = ("combined", "act", "select_goal")
TARGET_PRESET, TARGET_P99_US = "paper", 250.0


def peak_flops(size: int = 1024, repeats: int = 7) -> float:
    """FLOP/s of the best of ``repeats`` (size x size) @ (size x size) float32 matmuls on the current threads."""
    a, b = torch.randn(size, size), torch.randn(size, size)
    torch.mm(a, b)
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        torch.mm(a, b)
        best = min(best, time.perf_counter() - start)
    return 2.0 * size ** 3 / best


def linear_macs(module: torch.nn.Module) -> int:
    """Multiply-adds of one row through every Linear layer of ``module``."""
    return sum(m.in_features * m.out_features for m in module.modules() if isinstance(m, torch.nn.Linear))


def timed_calls(step, inputs: list[tuple[np.ndarray, np.ndarray]], count: int) -> tuple[list[float], list[float]]:
    """Wall and thread-CPU microseconds of ``count`` calls of ``step(obs, meta_obs)``."""
    wall, cpu = [], []
    for i in range(count):
        obs, meta_obs = inputs[i % len(inputs)]
        w, c = time.perf_counter_ns(), time.thread_time_ns()
        step(obs, meta_obs)
        cpu.append((time.thread_time_ns() - c) / 1e3)
        wall.append((time.perf_counter_ns() - w) / 1e3)
    return wall, cpu


def bare_linear_reference() -> Callable[[np.ndarray, np.ndarray], None]:
    """A step of four bare 512 x 512 float32 F.linear calls at batch 1 (inputs ignored), under inference mode."""
    weights = [torch.randn(512, 512) for _ in range(4)]
    row = torch.randn(1, 512)

    def step(obs: np.ndarray, meta_obs: np.ndarray) -> None:
        with torch.inference_mode():
            hidden = row
            for weight in weights:
                hidden = torch.nn.functional.linear(hidden, weight)

    return step


def percentiles(values: list[float]) -> dict[str, float]:
    return {"p50": float(np.percentile(values, 50)), "p99": float(np.percentile(values, 99))}


def measure(policy: CheckpointPolicy, steps: int, blocks: int, folder: Path) -> dict:
    module = policy_module(policy)
    runners, sizes = {"eager": (policy.choose_goals, policy.act)}, {}
    for name, (fmt, precision) in ARTIFACTS.items():
        path = folder / f"policy-{name}.pt"
        manifest = build_manifest(policy, fmt, "0" * 64, precision=precision)
        path.write_bytes(artifact_bytes(policy_module(policy, precision), manifest))
        sizes[name] = path.stat().st_size
        runtime = load_policy(path)
        runners[name] = (runtime.select_goal, runtime.act)
    obs = record_observations(policy, count=500, envs=50)
    inputs = [(row[None, :], row[None, :META_OBS_DIM]) for row in obs]
    samples = {(r, c, kind): [] for r in RUNNERS for c in CALLS for kind in ("wall", "cpu")}
    reference, reference_wall = bare_linear_reference(), []
    timed_calls(reference, inputs, 200)
    for block in range(blocks):
        reference_wall += timed_calls(reference, inputs, max(1, steps // blocks))[0]
        for runner in RUNNERS:
            select_goal, act = runners[runner]
            calls = {"combined": lambda o, m: (select_goal(m), act(o)), "act": lambda o, m: act(o),
                     "select_goal": lambda o, m: select_goal(m)}
            for call, step in calls.items():
                if block == 0:
                    timed_calls(step, inputs, 200)  # warm-up: first calls (allocations, TorchScript profiling)
                wall, cpu = timed_calls(step, inputs, max(1, steps // blocks))
                samples[runner, call, "wall"] += wall
                samples[runner, call, "cpu"] += cpu
    latency = {runner: {call: {kind: percentiles(samples[runner, call, kind]) for kind in ("wall", "cpu")}
                        for call in CALLS} for runner in RUNNERS}
    macs = {"act": linear_macs(module.action_head), "select_goal": linear_macs(module.goal_head)}
    macs["combined"] = macs["act"] + macs["select_goal"]
    return {"actor_layers": list(policy.config.actor.layers), "meta_layers": list(policy.config.meta_actor.layers),
            "linear_macs": macs, "artifact_bytes": sizes, "latency_us": latency,
            "reference_four_512x512_linear_us": percentiles(reference_wall)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3_000, help="timed calls per runner and call kind")
    parser.add_argument("--blocks", type=int, default=6, help="turns the runners take (interleaved)")
    parser.add_argument("--presets", default="default,paper", help="comma-separated: default, paper")
    parser.add_argument("--checkpoint", default=None, help="time this run's policy instead of untrained presets")
    parser.add_argument("--out", default=results_file("policy_latency.json"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    if args.checkpoint:
        policies = {"checkpoint": CheckpointPolicy.load(args.checkpoint)}
    else:
        policies = {name.strip(): CheckpointPolicy.untrained(TrainConfig.from_preset(name.strip(), algo="hrl-sac"))
                    for name in args.presets.split(",") if name.strip()}
    peak = peak_flops()
    report: dict = {"torch_version": torch.__version__, "torch_threads": 1, "batch": 1, "timed_calls": args.steps,
                    "peak_matmul_gflops": peak / 1e9, "target": {"preset": TARGET_PRESET,
                                                                 "combined_p99_us": TARGET_P99_US}, "presets": {}}
    print(f"one thread, batch 1; peak of a 1024 x 1024 matmul: {peak / 1e9:.1f} GFLOP/s")
    with tempfile.TemporaryDirectory() as folder:
        for name, policy in policies.items():
            result = measure(policy, args.steps, args.blocks, Path(folder))
            bound = {call: 2.0 * macs / peak * 1e6 for call, macs in result["linear_macs"].items()}
            result["flop_lower_bound_us"] = bound
            report["presets"][name] = result
            print(f"\n{name}: actor {result['actor_layers']}, meta {result['meta_layers']}; artifacts "
                  + ", ".join(f"{fmt} {size / 1e6:.2f} MB" for fmt, size in result["artifact_bytes"].items()))
            print(f"  {'call':12s} {'lower bound':>12s}" + "".join(f" {r + ' p50/p99':>25s}" for r in RUNNERS))
            for call in CALLS:
                cells = "".join(f" {result['latency_us'][r][call]['wall']['p50']:12.1f}/"
                                f"{result['latency_us'][r][call]['wall']['p99']:<12.1f}" for r in RUNNERS)
                print(f"  {call:12s} {bound[call]:9.1f} us{cells}")
            ref = result["reference_four_512x512_linear_us"]
            print("  reference, four bare 512 x 512 F.linear at batch 1: "
                  f"p50 {ref['p50']:.1f} / p99 {ref['p99']:.1f} us")
            if name == TARGET_PRESET:
                verdict = {r: result["latency_us"][r]["combined"]["wall"]["p99"] <= TARGET_P99_US for r in RUNNERS}
                report["meets_target"] = verdict
                print(f"  target: combined p99 <= {TARGET_P99_US:.0f} us: "
                      + ", ".join(f"{r} {'meets' if ok else 'MISSES'}" for r, ok in verdict.items()))
    write_report(args.out, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
