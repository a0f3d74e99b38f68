"""One hidden layer of the default preset, timed in float32, in bfloat16 and under CPU autocast (one thread).

Why bfloat16 updates (``TrainConfig.update_dtype``) speed training up on one CPU and hardly at all on another
(docs/training.md): a bare bfloat16 matrix product may be fast while autocast, which casts the layer's input and
weight to bfloat16 at every call, spends the gain on those casts. Figures, microseconds per forward call of
``F.linear`` on a batch of 128 (median of --repeats runs of --calls calls each):
  * float32: input, weight and bias in float32 (the paper preset's precision);
  * bfloat16: input, weight and bias already in bfloat16 (the bare product);
  * autocast: float32 tensors under ``torch.autocast("cpu", torch.bfloat16)`` (what the SAC update did before
    ``policies.agents.networks.UpdateWeights``);
  * cached_weights: a float32 input cast to bfloat16, on weights already in bfloat16 (what the SAC update does now:
    ``UpdateWeights`` casts each weight once per value, not at every use);
  * weight_cast: casting the float32 weight to bfloat16 alone.

Usage: python benchmarks/bf16_layer.py [--inputs 276] [--units 256] [--calls 2000] [--repeats 5]
"""
from __future__ import annotations

import argparse
import sys
import time

import torch
import torch.nn.functional as F

from common import summarise, results_file, write_report

BATCH = 128


def microseconds_per_call(call, calls: int) -> float:
    for _ in range(50):  # warm up the kernels and caches
        call()
    start = time.perf_counter()
    for _ in range(calls):
        call()
    return (time.perf_counter() - start) / calls * 1e6


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--inputs", type=int, default=276, help="layer inputs (276: the observation)")
    parser.add_argument("--units", type=int, default=256, help="layer outputs (256: the default preset)")
    parser.add_argument("--calls", type=int, default=2_000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", default=results_file("bf16_layer.json"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    generator = torch.Generator().manual_seed(0)
    x = torch.randn(BATCH, args.inputs, generator=generator)
    weight = torch.randn(args.units, args.inputs, generator=generator)
    bias = torch.randn(args.units, generator=generator)
    x16, weight16, bias16 = x.bfloat16(), weight.bfloat16(), bias.bfloat16()

    def autocast_call():
        with torch.autocast("cpu", dtype=torch.bfloat16):
            return F.linear(x, weight, bias)

    calls = {"float32_us": lambda: F.linear(x, weight, bias), "bfloat16_us": lambda: F.linear(x16, weight16, bias16),
             "autocast_us": autocast_call, "cached_weights_us": lambda: F.linear(x.bfloat16(), weight16, bias16),
             "weight_cast_us": lambda: weight.bfloat16()}
    runs: dict[str, list[float]] = {name: [] for name in calls}
    for _ in range(args.repeats):
        for name, call in calls.items():  # taking turns inside every repeat, so drift hits all alike
            runs[name].append(microseconds_per_call(call, args.calls))
    medians = summarise(runs, f"one {args.inputs} -> {args.units} layer, batch {BATCH}, one thread: us per call "
                              f"(median of {args.repeats} runs of {args.calls:,} calls)")
    print(f"  bfloat16 gain: bare {medians['float32_us'] / medians['bfloat16_us']:.2f}x, "
          f"under autocast {medians['float32_us'] / medians['autocast_us']:.2f}x, "
          f"cached weights {medians['float32_us'] / medians['cached_weights_us']:.2f}x")
    write_report(args.out, {"batch": BATCH, "inputs": args.inputs, "units": args.units, "calls": args.calls,
                            "repeats": args.repeats, "medians": medians, "runs": runs})
    return 0


if __name__ == "__main__":
    sys.exit(main())
