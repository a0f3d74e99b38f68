"""Learning reliability across seeds: the easy missions of tests/easy_missions.py, by algorithm and update precision.

tests/test_learning.py trains one seed per algorithm and asks for +20 points of success. Whether that one seed
learns says little about the learner; this script trains the same configuration (the test's own missions,
networks, budget and settings, imported from it) over several seeds, in float32 and in bfloat16 updates, and
prints each run's deterministic success before and after training on the test's 32 evaluation episodes, then how
many runs gained the +20 points of success the test asks for and how many pass all of its checks
(``learning_checks`` in the test: success, reward and the training episodes' own success).

Each run is one process-independent Trainer on one torch thread; ``--workers`` runs that many at once. The oneDNN
kernels, and so the bfloat16 bits, depend on the CPU (AMX or AVX-512 BF16; ``ONEDNN_MAX_CPU_ISA=AVX512_CORE_BF16``
forces the latter on an AMX machine), so the report records which the machine offers.

``--first-layer-float32`` is an experiment, not a feature: it patches ``networks.UpdateWeights.hidden`` (and the
critics' bfloat16 first-layer shortcut) so that in bfloat16 updates the first Linear layer of every network runs in
float32 on the float32 observations (the rest as before), to test whether the inputs' rounding to bfloat16 (8 bits
of mantissa for goal offsets and positions) is what costs HRL-SAC's learning.

Usage: python benchmarks/easy_learning.py [--algos hrl-sac,sac] [--dtypes float32,bfloat16] [--seeds 0-4]
                                          [--workers 2] [--first-layer-float32]
                                          [--out benchmarks/results/easy_learning.json]
"""
from __future__ import annotations

import argparse
import os
import pathlib
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

from common import results_file, write_report  # noqa: E402


def first_layer_in_float32() -> None:
    """The --first-layer-float32 experiment: patch the update's bfloat16 passes (see the module docstring)."""
    import torch
    import torch.nn.functional as F
    from torch import nn

    from policies.agents import networks

    if getattr(networks.UpdateWeights, "first_layer_float32", False):
        return  # this worker process is patched already
    original_hidden = networks.UpdateWeights.hidden

    def hidden(self, layers, x, frozen=False):
        layers = list(layers)
        first = next((i for i, layer in enumerate(layers) if isinstance(layer, nn.Linear)), None)
        if self.dtype != torch.bfloat16 or first is None:
            return original_hidden(self, layers, x, frozen)
        x = original_hidden(self, layers[:first], x, frozen)
        linear = layers[first]
        x = F.linear(x.float(), self.as_is(linear.weight, frozen), self.as_is(linear.bias, frozen)).to(self.dtype)
        return original_hidden(self, layers[first + 1:], x, frozen)

    def twin_q_forward_with(self, obs, act, weights, frozen=False):  # without ActionGradientOnly's bfloat16 layer
        x = torch.cat([obs, act], dim=-1)
        return tuple(weights.output(net[-1], weights.hidden(list(net)[:-1], x, frozen).float(), frozen).squeeze(-1)
                     for net in (self.q1, self.q2))

    networks.UpdateWeights.hidden = hidden
    networks.UpdateWeights.first_layer_float32 = True
    networks.TwinQ.forward_with = twin_q_forward_with


def train_once(algo: str, dtype: str, seed: int, first_layer_float32: bool = False) -> dict:
    """One run of the test's configuration with ``seed`` and ``update_dtype``; success before and after."""
    import torch

    import easy_missions as easy

    if first_layer_float32:
        first_layer_in_float32()
    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as tmp:
        trainer = easy.easy_trainer(pathlib.Path(tmp), algo, seed, update_dtype=dtype)
        before = easy.evaluate(trainer)
        started = time.perf_counter()
        trainer.run(progress=False)
        after = easy.evaluate(trainer)
        checks = easy.learning_checks(before, after, trainer)
        train_success = float(sum(episode[0] for episode in trainer.recent) / max(len(trainer.recent), 1))
    label = dtype + ("-first-layer-float32" if first_layer_float32 else "")
    return {"algo": algo, "dtype": label, "seed": seed, "success_before": before["success_rate"],
            "success_after": after["success_rate"], "reward_before": before["reward_mean"],
            "reward_after": after["reward_mean"], "training_success": train_success,
            "learned": checks["success +20 points"],
            "passes_the_test": all(checks.values()), "checks": checks,
            "seconds": round(time.perf_counter() - started, 1)}


def easy_steps() -> dict[str, int]:
    """The test's training budgets per algorithm."""
    import easy_missions

    return easy_missions.STEPS


def parse_seeds(text: str) -> list[int]:
    if "-" in text:
        first, last = text.split("-")
        return list(range(int(first), int(last) + 1))
    return [int(s) for s in text.split(",")]


def cpu_isa() -> list[str]:
    try:
        flags = next(line for line in open("/proc/cpuinfo") if line.startswith("flags")).split()
    except (OSError, StopIteration):
        return []
    return [flag for flag in ("avx512f", "avx512_bf16", "amx_bf16") if flag in flags]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--algos", default="hrl-sac,sac")
    parser.add_argument("--dtypes", default="float32,bfloat16")
    parser.add_argument("--seeds", default="0-4", help="a range (0-4) or a list (0,2,5)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--first-layer-float32", action="store_true",
                        help="experiment: bfloat16 updates with each network's first layer in float32")
    parser.add_argument("--out", default=results_file("easy_learning.json"))
    args = parser.parse_args()
    algos = [a for a in args.algos.split(",") if a]
    dtypes = [d for d in args.dtypes.split(",") if d]
    if bad := [a for a in algos if a not in easy_steps()]:
        parser.error(f"unknown algorithm(s) {bad}; choose from {', '.join(easy_steps())}")
    if bad := [d for d in dtypes if d not in ("float32", "bfloat16")]:
        parser.error(f"unknown dtype(s) {bad}; choose from float32, bfloat16")
    jobs = [(algo, dtype, seed) for algo in algos for dtype in dtypes for seed in parse_seeds(args.seeds)]
    runs = []
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        for run in pool.map(train_once, *zip(*jobs), [args.first_layer_float32] * len(jobs)):
            runs.append(run)
            print(f"{run['algo']:8s} {run['dtype']:9s} seed {run['seed']}: success {run['success_before']:.3f} -> "
                  f"{run['success_after']:.3f}, training episodes {run['training_success']:.2f}, test checks "
                  f"{'pass' if run['passes_the_test'] else 'FAIL'} ({run['seconds']:.0f} s)", flush=True)
    summary = {}
    for algo in algos:
        for dtype in dtypes:
            mine = [r for r in runs if r["algo"] == algo and r["dtype"].startswith(dtype)]
            label = mine[0]["dtype"] if mine else dtype
            summary[f"{algo}/{label}"] = {"learned": sum(r["learned"] for r in mine),
                                          "passes_the_test": sum(r["passes_the_test"] for r in mine),
                                          "runs": len(mine)}
            print(f"{algo} {label}: {summary[f'{algo}/{label}']['learned']} of {len(mine)} seeds gained "
                  f"+20 points of success; {summary[f'{algo}/{label}']['passes_the_test']} pass all of the "
                  f"test's checks")
    write_report(args.out, {"cpu_flags": cpu_isa(), "onednn_max_cpu_isa": os.environ.get("ONEDNN_MAX_CPU_ISA"),
                            "steps": easy_steps(), "summary": summary, "runs": runs})
    return 0


if __name__ == "__main__":
    sys.exit(main())
