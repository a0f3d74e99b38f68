"""Training speed: flat SAC environment steps per second with one gradient update per step, ours vs Stable-Baselines3.

For each network preset both agents train on the same task (--task: SarSearch-v1 by default, the task every policy
is trained on; SarSearch-v0, the paper's, has a lighter environment step), with the same flight settings and
scenario split, one gradient update of batch 128 per environment step, one environment, one torch thread, in the
same run (the agents take turns inside every repeat, so a change of machine load hits all of them alike). The
environment step is the same work for both, so the heavier it is, the closer the ratio comes to 1:

  * ours:      policies.training.trainer.Trainer (what ``hrlsac train --algo sac`` runs), num_envs=1,
               updates_per_step=1.0, the preset's networks (LayerNorm after each hidden layer, no dropout), float32
               updates: the default preset as shipped (docs/training.md says why float32).
  * ours_noln: the same without LayerNorm -- exactly SB3's network shape (SB3's MlpPolicy has no LayerNorm).
  * ours_bf16, ours_noln_bf16: the two above with ``TrainConfig.update_dtype="bfloat16"`` (the hidden layers'
               matrix products of each update in bfloat16 with CPU autocast's arithmetic; weights, Adam, outputs and
               losses float32), an opt-in speed option. The same work per step; the speed-up needs AVX-512 BF16 or AMX.
  * sb3:       stable_baselines3.SAC("MlpPolicy", train_freq=1, gradient_steps=1, batch_size=128,
               learning_starts=--warmup, net_arch=hidden widths, device="cpu") on policies.env.gym_env.SarSearchEnv.
  * ours_vec8: extra line, NOT the same work: our vectorised configuration, num_envs=8 and updates_per_step=0.125
               (one update per 8 environment steps).

Only steady-state training is timed: each run first takes --warmup uniformly random steps (untimed; learning starts
at its end), then the clock runs over the next --steps (--steps-3x512) steps. Our final checkpoint (run() always
writes one) is outside the clock; checkpoint_every and log_every are set past the end of the run.

Ours still does more per step than SB3: prioritised replay (sum-tree sampling, importance weights, priority
updates) and the running observation normaliser, which SB3's uniform replay and raw observations do not have.

Figures: steps/s by the wall clock (the headline; medians over --repeats) and by process CPU time (less sensitive
to other processes on a shared machine). Targets: ours >= 1.5 x SB3 at the default preset (2 x 256) and >= 1.1 x
at 3 x 512.

Usage: python benchmarks/train_speed.py [--steps 2000] [--steps-3x512 600] [--warmup 1000] [--repeats 3]
                                        [--presets default,3x512] [--task SarSearch-v1]
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time

import torch

from common import summarise, results_file, write_report  # first: it puts this checkout on sys.path

from policies.config import NetworkConfig, TrainConfig
from policies.env.gym_env import SarSearchEnv
from policies.env.core import SarSearchConfig
from policies.evaluation.parallel import quick_evaluation
from policies.training.trainer import Trainer

PRESETS = {"default": (256, 256), "3x512": (512, 512, 512)}
TARGETS = {"default": 1.5, "3x512": 1.1}
BATCH_SIZE = 128
BUFFER_SIZE = 100_000
AGENTS = ("ours", "ours_noln", "ours_bf16", "ours_noln_bf16", "sb3", "ours_vec8")
LABELS = {"ours": "ours (LayerNorm, float32)", "ours_noln": "ours (no LayerNorm = SB3 shape)",
          "ours_bf16": "ours (LayerNorm, bfloat16 updates)", "ours_noln_bf16": "ours (SB3 shape, bfloat16)",
          "sb3": "Stable-Baselines3 SAC", "ours_vec8": "ours, 8 envs, 1 update / 8 steps"}


def our_config(hidden: tuple[int, ...], layer_norm: bool, num_envs: int, updates_per_step: float, warmup: int,
               steps: int, seed: int, update_dtype: str = "float32", task: str = "SarSearch-v1") -> TrainConfig:
    net = NetworkConfig(hidden=hidden, layer_norm=layer_norm, dropout=0.0)
    return TrainConfig.from_preset("default", algo="sac", seed=seed, num_envs=num_envs,
                                   updates_per_step=updates_per_step, warmup_steps=warmup, total_steps=warmup + steps,
                                   batch_size=BATCH_SIZE, buffer_size=BUFFER_SIZE, actor=net, critic=net,
                                   checkpoint_every=10**9, log_every=10**9, torch_threads=1, update_dtype=update_dtype,
                                   task=task)


def time_ours(config: TrainConfig, warmup: int, steps: int) -> tuple[float, float]:
    """(wall, CPU) steps/s of Trainer.run over ``steps`` steps after ``warmup`` untimed random ones."""
    with tempfile.TemporaryDirectory() as run_dir:
        trainer = Trainer(config, run_dir, evaluate=quick_evaluation)
        trainer.run(progress=False, stop_at=warmup)
        clock: dict[str, tuple[float, float]] = {}
        save = trainer.save

        def save_after_clock():  # run() ends with a checkpoint: stop the clock first
            clock.setdefault("end", (time.perf_counter(), time.process_time()))
            return save()

        trainer.save = save_after_clock
        first, first_updates = trainer.step, trainer.low.num_updates
        wall, cpu = time.perf_counter(), time.process_time()
        trainer.run(progress=False, stop_at=warmup + steps)
        done, updates = trainer.step - first, trainer.low.num_updates - first_updates
        expected = round(done * config.updates_per_step)
        if done != steps or updates != expected:
            raise RuntimeError(f"ours: timed {done} steps with {updates} updates, expected {steps} and {expected}")
        return done / (clock["end"][0] - wall), done / (clock["end"][1] - cpu)


def time_sb3(hidden: tuple[int, ...], flight, warmup: int, steps: int, seed: int,
             task: str = "SarSearch-v1") -> tuple[float, float]:
    """(wall, CPU) steps/s of SB3's SAC.learn over ``steps`` steps after ``warmup`` untimed random ones."""
    from stable_baselines3 import SAC as SB3SAC

    model = SB3SAC("MlpPolicy", SarSearchEnv(SarSearchConfig(flight=flight, task=task)), learning_rate=3e-4,
                   buffer_size=BUFFER_SIZE, learning_starts=warmup, batch_size=BATCH_SIZE, tau=0.005, gamma=0.99,
                   train_freq=1, gradient_steps=1, policy_kwargs={"net_arch": list(hidden)}, device="cpu", seed=seed,
                   verbose=0)
    model.learn(warmup)  # random actions only: SB3 trains once num_timesteps > learning_starts
    first, first_updates = model.num_timesteps, model._n_updates
    wall, cpu = time.perf_counter(), time.process_time()
    model.learn(steps, reset_num_timesteps=False)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    done, updates = model.num_timesteps - first, model._n_updates - first_updates
    if done != steps or updates != steps:
        raise RuntimeError(f"sb3: timed {done} steps with {updates} updates, expected {steps} of each")
    return done / wall, done / cpu


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2_000, help="timed steps per run at the default preset")
    parser.add_argument("--steps-3x512", type=int, default=600, help="timed steps per run at 3 x 512")
    parser.add_argument("--warmup", type=int, default=1_000, help="untimed random steps before each timed run")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--presets", default="default,3x512", help=f"comma-separated, from {', '.join(PRESETS)}")
    parser.add_argument("--task", default="SarSearch-v1", choices=["SarSearch-v1", "SarSearch-v0"])
    parser.add_argument("--agents", default=",".join(AGENTS),
                        help="comma-separated subset of the agents above (sb3 and ours always run: the ratio); "
                             "without hardware bfloat16 the bf16 ones run at a fraction of the others' speed")
    parser.add_argument("--out", default=results_file("train_speed.json"))
    args = parser.parse_args()
    agents = [agent for agent in AGENTS if agent in {"ours", "sb3", *(a.strip() for a in args.agents.split(","))}]
    if unknown := [a.strip() for a in args.agents.split(",") if a.strip() and a.strip() not in AGENTS]:
        parser.error(f"unknown agent(s) {unknown}; choose from {', '.join(AGENTS)}")
    presets = [name.strip() for name in args.presets.split(",") if name.strip()]
    if unknown := [name for name in presets if name not in PRESETS]:
        parser.error(f"unknown preset(s) {unknown}; choose from {', '.join(PRESETS)}")
    if args.warmup % 8 or args.warmup < BATCH_SIZE:
        parser.error("--warmup must be a multiple of 8 (the vectorised run) and at least the batch size")
    torch.set_num_threads(1)
    flight = TrainConfig().flight
    steps = {"default": args.steps, "3x512": args.steps_3x512}
    steps = {name: max(8, steps[name] // 8 * 8) for name in presets}  # whole vector steps for ours_vec8

    report: dict = {"agents": agents, "task": args.task, "warmup_steps": args.warmup, "timed_steps": steps,
                    "repeats": args.repeats, "torch_threads": 1, "batch_size": BATCH_SIZE,
                    "targets": {name: TARGETS[name] for name in presets}, "presets": {}}
    table = []
    for name in presets:
        hidden, n = PRESETS[name], steps[name]
        wall: dict[str, list[float]] = {agent: [] for agent in agents}
        cpu: dict[str, list[float]] = {agent: [] for agent in agents}
        for repeat in range(args.repeats):
            def ours(layer_norm: bool, num_envs: int = 1, updates_per_step: float = 1.0, dtype: str = "float32"):
                config = our_config(hidden, layer_norm, num_envs, updates_per_step, args.warmup, n, repeat, dtype,
                                    args.task)
                return lambda: time_ours(config, args.warmup, n)

            runs = {
                "ours": ours(True), "ours_noln": ours(False),
                "ours_bf16": ours(True, dtype="bfloat16"), "ours_noln_bf16": ours(False, dtype="bfloat16"),
                "sb3": lambda: time_sb3(hidden, flight, args.warmup, n, repeat, args.task),
                "ours_vec8": ours(True, num_envs=8, updates_per_step=0.125),
            }
            for agent in agents:
                w, c = runs[agent]()
                wall[agent].append(w)
                cpu[agent].append(c)
            print(f"{name} run {repeat + 1}/{args.repeats}: "
                  + ", ".join(f"{agent} {wall[agent][-1]:,.1f}/s" for agent in agents), flush=True)
        medians = summarise({f"{agent}_steps_per_s": wall[agent] for agent in agents},
                            f"{name} ({' x '.join(map(str, hidden))}): wall-clock steps/s, medians over "
                            f"{args.repeats} runs of {n:,} timed steps")
        cpu_medians = {agent: statistics.median(cpu[agent]) for agent in agents}
        ratio = {agent: medians[f"{agent}_steps_per_s"] / medians["sb3_steps_per_s"] for agent in agents}
        cpu_ratio = {agent: cpu_medians[agent] / cpu_medians["sb3"] for agent in agents}
        report["presets"][name] = {
            "hidden": list(hidden), "timed_steps": n, "medians_wall_steps_per_s": medians,
            "medians_cpu_steps_per_s": {f"{agent}_steps_per_s": v for agent, v in cpu_medians.items()},
            "ratio_to_sb3_wall": ratio, "ratio_to_sb3_cpu": cpu_ratio,
            "runs_wall_steps_per_s": wall, "runs_cpu_steps_per_s": cpu,
        }
        table.append((name, hidden, medians, cpu_medians, ratio, cpu_ratio))

    print("\nflat SAC training, one env, 1 update of batch 128 per env step, 1 torch thread (medians):")
    print(f"  {'preset':9s} {'agent':34s} {'steps/s':>9s} {'x SB3':>7s} {'CPU steps/s':>12s} {'x SB3':>7s}")
    for name, hidden, medians, cpu_medians, ratio, cpu_ratio in table:
        for agent in agents:
            extra = "   (not the same work)" if agent == "ours_vec8" else ""
            print(f"  {name:9s} {LABELS[agent]:34s} {medians[f'{agent}_steps_per_s']:9,.1f} {ratio[agent]:6.2f}x "
                  f"{cpu_medians[agent]:12,.1f} {cpu_ratio[agent]:6.2f}x{extra}")
    verdicts = {}
    for name, hidden, medians, cpu_medians, ratio, cpu_ratio in table:
        target = TARGETS[name]
        compared = [a for a in ("ours", "ours_noln", "ours_bf16", "ours_noln_bf16") if a in agents]  # SB3's work
        verdicts[name] = {agent: bool(ratio[agent] >= target) for agent in compared}
        print(f"{name} ({' x '.join(map(str, hidden))}), target >= {target}x SB3: " + "; ".join(
            f"{LABELS[agent]} {ratio[agent]:.2f}x -> {'meets' if verdicts[name][agent] else 'MISSES'}"
            for agent in compared))
    report["meets_target"] = verdicts
    write_report(args.out, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
