"""Stable-Baselines3's SAC brought as your own policy: trained on SarSearch-v1 with the flat SAC baseline's step
budget and environment, exported with ``hrlsac export --from-sb3`` and evaluated as the project evaluates its runs.

* Training: ``stable_baselines3.SAC("MlpPolicy")`` on ``gymnasium.make("SarSearch-v1", action_frame="arrive")`` (the
  train split, the default flight settings), ``--steps`` environment steps (default 200,000): the budget and the
  environment of the flat SAC in docs/results/sac.sweep.yaml. SB3's SAC as a gymnasium user runs it: one
  environment, the environment's own reward (no shaping), raw observations, uniform replay, no LayerNorm. Where
  both have the setting, it takes the project's defaults (``policies.config``): 2 x 256, learning rate 3e-4,
  gamma 0.99, tau 0.005, batch 128, a 100,000-transition buffer, 2,000 random warm-up steps and an update every
  second step (``updates_per_step`` 0.5).
* Export: the model zip through ``policies.export.sb3.export_sb3_policy`` (parity-checked against SB3's predict).
* Evaluation: the artifact, loaded by the on-board runtime, on the first ``--episodes`` val scenarios with
  ``policies.evaluation`` under the environment's rules and under the mission runner's rules (``--flight-rules``),
  as ``hrlsac evaluate`` judges the project's runs; beside it, the same scenarios flown by ``--reference`` (the
  shipped flat SAC, ``policies/pretrained/sac.pt``; ``--reference ''`` for none).

Ctrl-C during training saves the model trained so far (and exits without evaluating). Writes
benchmarks/results/sb3_sac.json, the model zip and the artifact to ``--work``.

Usage: python benchmarks/sb3_sac.py [--seed 0] [--steps 200000] [--episodes 500] [--work runs/sb3-sac/seed0]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import torch
from common import ROOT, results_file, write_report

import gymnasium

import policies  # noqa: F401  (registers SarSearch-v1)
from autonomy.policy import Policy, load_policy
from hrlsac_cli.progress import progress_bar
from missions.mission import FlightSettings
from policies.config import TrainConfig
from policies.evaluation.episodes import episode_batch, run_episodes, summarise
from policies.evaluation.parallel import padded
from policies.export.sb3 import export_sb3_policy, import_sb3

ENV_KWARGS = {"action_frame": "arrive"}
"""The flat SAC baseline's environment (docs/results/sac.sweep.yaml) beyond gymnasium.make's defaults."""
BASELINE_STEPS = 200_000
"""The flat SAC baseline's step budget (docs/results/sac.sweep.yaml)."""


def sb3_settings() -> dict:
    """SB3 SAC's keyword arguments: the project's defaults where both have the setting (see the module docstring)."""
    low_level = TrainConfig()
    hidden = list(low_level.actor.hidden)
    return {"learning_rate": low_level.learning_rate, "gamma": low_level.gamma, "tau": low_level.tau,
            "batch_size": low_level.batch_size, "buffer_size": low_level.buffer_size,
            "learning_starts": low_level.warmup_steps, "train_freq": round(1 / low_level.updates_per_step),
            "gradient_steps": 1, "policy_kwargs": {"net_arch": hidden}}


def train(seed: int, steps: int, model_zip: Path) -> tuple[object, float, bool]:
    """SB3 SAC trained for ``steps`` steps and saved to ``model_zip``; its wall time and whether it ran to the end
    (False: interrupted, the model so far saved)."""
    sb3 = import_sb3()
    from stable_baselines3.common.callbacks import BaseCallback

    class Progress(BaseCallback):
        def __init__(self, bar):
            super().__init__()
            self.bar = bar

        def _on_step(self) -> bool:
            self.bar.advance_to(self.num_timesteps)
            return True

    env = gymnasium.make("SarSearch-v1", split="train", **ENV_KWARGS)
    model = sb3.SAC("MlpPolicy", env, seed=seed, device="cpu", **sb3_settings())
    started, finished = time.perf_counter(), True
    with progress_bar(steps, "step", "training SB3 SAC") as bar:
        try:
            model.learn(total_timesteps=steps, callback=Progress(bar))
        except KeyboardInterrupt:
            finished = False
    model.save(model_zip)
    return model, time.perf_counter() - started, finished


def evaluate(policy: Policy, flight: FlightSettings, action_frame: str, split: str, episodes: int,
             flight_rules: bool, label: str) -> dict:
    """``policies.evaluation``'s metrics of the flat ``policy`` on the first ``episodes`` scenarios of ``split``."""
    core = episode_batch(split, episodes, flight, goal_conditioned=False, task="SarSearch-v1",
                         action_frame=action_frame)
    act = padded(policy.act)
    with progress_bar(episodes, "episode", label) as bar:
        record = run_episodes(core, lambda batch: act(batch.obs), flight_rules=flight_rules,
                              on_progress=bar.advance_to)
    metrics = summarise(record, flight.step_period_s)
    metrics["per_episode"] = {"success": metrics["per_episode"]["success"]}
    return metrics


def evaluate_both_rules(path: Path, split: str, episodes: int) -> dict:
    """An artifact's metrics under the environment's rules and under the mission runner's."""
    policy = load_policy(path)
    trained = policy.manifest.training_config
    flight, frame = FlightSettings(**trained["flight"]), trained.get("action_frame", "north_east")
    out = {"policy": str(path), "policy_sha256": policy.sha256, "algorithm": policy.manifest.algorithm}
    for name, rules in (("environment_rules", False), ("runner_rules", True)):
        out[name] = evaluate(policy, flight, frame, split, episodes, rules, f"{path.name}, {name.replace('_', ' ')}")
        low, high = out[name]["success_ci95"]
        print(f"  {path.name:14s} {name:18s} success {out[name]['success_rate']:6.1%} [{low:.1%}, {high:.1%}], "
              f"ran dry {out[name]['ran_dry_rate']:.1%}, reward {out[name]['reward_mean']:.1f}")
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--steps", type=int, default=BASELINE_STEPS,
                        help=f"environment steps to train for (default {BASELINE_STEPS:,}: the flat SAC baseline's)")
    parser.add_argument("--episodes", type=int, default=500, help="val scenarios evaluated on (default 500)")
    parser.add_argument("--work", default=None, help="folder for model.zip and sb3-sac.pt (default runs/sb3-sac/seedN)")
    parser.add_argument("--reference", default=os.path.join(ROOT, "policies", "pretrained", "sac.pt"),
                        help="an artifact evaluated on the same scenarios (default the shipped flat SAC; '' for none)")
    parser.add_argument("--out", default=results_file("sb3_sac.json"))
    args = parser.parse_args()
    if args.steps < 1 or args.episodes < 1:
        parser.error("--steps and --episodes must be >= 1")
    try:
        import_sb3()
    except ImportError as exc:
        parser.error(str(exc))
    torch.set_num_threads(1)
    work = Path(args.work or os.path.join(ROOT, "runs", "sb3-sac", f"seed{args.seed}"))
    work.mkdir(parents=True, exist_ok=True)
    model_zip, artifact = work / "model.zip", work / "sb3-sac.pt"
    model, train_s, finished = train(args.seed, args.steps, model_zip)
    if not finished:
        print(f"interrupted after {model.num_timesteps:,} steps: the model so far is in {model_zip} (export it with "
              f"hrlsac export --from-sb3 {model_zip} -o {artifact} --env-kwargs '{{\"action_frame\": \"arrive\"}}')",
              file=sys.stderr)
        return 130
    print(f"trained {model.num_timesteps:,} steps in {train_s:.0f} s ({model.num_timesteps / train_s:.1f} steps/s): "
          f"{model_zip}")
    exported = export_sb3_policy(model_zip, artifact, env_kwargs=ENV_KWARGS)
    print(f"exported {artifact}: parity with SB3's predict {exported.parity.summary()}")
    started = time.perf_counter()
    results = {"sb3_sac": evaluate_both_rules(artifact, "val", args.episodes)}
    if args.reference:
        results["reference"] = evaluate_both_rules(Path(args.reference), "val", args.episodes)
    episodes = [info["r"] for info in model.ep_info_buffer]
    write_report(args.out, {
        "seed": args.seed, "steps": int(model.num_timesteps), "baseline_steps": BASELINE_STEPS,
        "environment": {"task": "SarSearch-v1", "split": "train", **ENV_KWARGS}, "sb3_settings": sb3_settings(),
        "stable_baselines3": import_sb3().__version__, "model_zip": str(model_zip), "artifact": str(artifact),
        "parity": exported.parity.summary(), "split": "val", "episodes": args.episodes,
        "train_last_episodes_reward_mean": sum(episodes) / len(episodes) if episodes else None,
        **results, "wall_s": {"train": train_s, "evaluate": time.perf_counter() - started}, "torch_threads": 1})
    return 0


if __name__ == "__main__":
    sys.exit(main())
