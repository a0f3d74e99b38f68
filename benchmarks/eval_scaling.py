"""Evaluation throughput (episodes per second) at 1 and 2 workers, on local processes and on Ray.

Figures (median of --repeats evaluations of the same checkpoint on the first --episodes test scenarios):
  * serial_episodes_per_s: ``hrlsac evaluate`` in one process (one torch thread);
  * processes_2_episodes_per_s: ``--workers 2`` (two spawned processes; each call starts them, so the time
    includes their start-up, also measured alone as process_pool_startup_s: two processes that start, import
    torch and the evaluation modules, and return);
  * ray_1_episodes_per_s / ray_2_episodes_per_s: ``--ray`` on a local Ray instance with 2 CPUs, 1 and 2 workers
    (Ray keeps its worker processes, so after the untimed warm-up run there is no start-up in the time);
  * parallel efficiency = throughput at 2 workers / (2 x throughput at 1 worker).

Every parallel result is checked equal to the serial one before it is timed. The machine this was measured on
has 2 cores shared with other jobs: 2 workers can at best double the throughput, and less when the other jobs
are busy.

Usage: python benchmarks/eval_scaling.py [--run RUN] [--episodes 1000] [--repeats 3]
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time

import torch
from common import results_file, summarise, write_report

from policies.config import TrainConfig
from policies.evaluation.parallel import evaluate_checkpoint
from policies.evaluation.parallel import quick_evaluation
from policies.training.trainer import Trainer
from simulation.worker_pool import PoolConfig, run_tasks, start_local_ray

MACHINE_NOTE = "2 cores, shared with other jobs (parallel efficiency is bounded by what the other jobs leave free)"


def train_checkpoint(folder: str, steps: int) -> str:
    """A short default-preset HRL-SAC run (its networks have the shipped policies' sizes)."""
    config = TrainConfig.from_preset("default", total_steps=steps, seed=0, buffer_size=10_000, eval_every=0)
    Trainer(config, folder, evaluate=quick_evaluation).run(progress=False)
    return folder


def started(_: int) -> int:
    """A task that does nothing: on a fresh process its time is the worker start-up (this script's imports:
    torch and the evaluation modules)."""
    return os.getpid()


def startup_s() -> float:
    """Wall time of two local worker processes that start, import, and do nothing."""
    start = time.perf_counter()
    run_tasks(started, [0, 1], PoolConfig(workers=2))
    return time.perf_counter() - start


def timed(run: str, episodes: int, pool: PoolConfig, serial: dict | None) -> float:
    """Episodes per second of one evaluation on ``pool`` (its metrics checked equal to the serial ones)."""
    start = time.perf_counter()
    metrics = evaluate_checkpoint(run, "test", episodes, pool)
    elapsed = time.perf_counter() - start
    if serial is not None and metrics != serial:
        raise SystemExit(f"parallel evaluation on {pool.describe()} differs from the serial one")
    return episodes / elapsed


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", default=None, help="run folder to evaluate (default: train a short one)")
    parser.add_argument("--train-steps", type=int, default=3_000, help="steps of the default run")
    parser.add_argument("--episodes", type=int, default=1_000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", default=results_file("eval_scaling.json"))
    args = parser.parse_args()
    import ray

    load_before = os.getloadavg()[0]
    start_local_ray(num_cpus=2)
    with tempfile.TemporaryDirectory() as scratch:
        run = args.run or train_checkpoint(os.path.join(scratch, "run"), args.train_steps)
        serial = evaluate_checkpoint(run, "test", args.episodes)
        pools = {"serial": PoolConfig(), "processes_2": PoolConfig(workers=2),
                 "ray_1": PoolConfig(workers=1, ray_address="local"),
                 "ray_2": PoolConfig(workers=2, ray_address="local")}
        for name in ("ray_1", "ray_2"):  # warm-up: Ray starts its worker processes once
            timed(run, args.episodes, pools[name], serial)
        runs: dict[str, list[float]] = {f"{name}_episodes_per_s": [] for name in pools}
        runs["process_pool_startup_s"] = []
        for repeat in range(args.repeats):
            for name, pool in pools.items():
                runs[f"{name}_episodes_per_s"].append(timed(run, args.episodes, pool, serial))
            runs["process_pool_startup_s"].append(startup_s())
            print(f"  repeat {repeat}: " + ", ".join(f"{key} {values[-1]:.1f}" for key, values in runs.items()),
                  file=sys.stderr)
    ray.shutdown()
    medians = summarise(runs, f"evaluation of {args.episodes} test episodes (HRL-SAC, "
                              f"{'given run' if args.run else f'{args.train_steps:,}-step default-preset run'})")
    efficiency = {"processes_2": medians["processes_2_episodes_per_s"] / (2 * medians["serial_episodes_per_s"]),
                  "ray_2": medians["ray_2_episodes_per_s"] / (2 * medians["ray_1_episodes_per_s"])}
    print(f"  parallel efficiency at 2 workers: local processes {efficiency['processes_2']:.0%} (vs serial), "
          f"Ray {efficiency['ray_2']:.0%} (vs Ray with 1 worker)")
    load = (load_before, os.getloadavg()[0])
    print(f"  machine: {os.cpu_count()} CPUs; {MACHINE_NOTE}; 1-minute load average {load[0]:.1f} before, "
          f"{load[1]:.1f} after")
    print(f"  every parallel result was equal to the serial one ({serial['success_rate']:.1%} success, mean episode "
          f"length {serial['length_mean']:.0f} steps)")
    write_report(args.out, {"episodes": args.episodes, "repeats": args.repeats, "run": args.run or "trained",
                            "train_steps": None if args.run else args.train_steps,
                            "mean_episode_length": serial["length_mean"], "medians": medians, "runs": runs,
                            "parallel_efficiency": efficiency, "cpus": os.cpu_count(), "machine": MACHINE_NOTE,
                            "load_average_before_after": load,
                            "python": platform.python_version(), "torch": torch.__version__, "ray": ray.__version__})
    return 0


if __name__ == "__main__":
    sys.exit(main())
