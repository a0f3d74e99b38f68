"""``hrlsac train``: HRL-SAC or flat SAC on SarSearch-v1 or v0 (--set task=...) into a run folder (resumable)."""
from __future__ import annotations

import argparse
import dataclasses
import json
import signal
import sys
from pathlib import Path

from policies.checkpoint import CHECKPOINT


def build_parser(prog: str) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__.split(":", 1)[1].strip(),
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--algo", choices=["hrl-sac", "sac"], default="hrl-sac")
    parser.add_argument("--preset", choices=["default", "paper"], default="default")
    parser.add_argument("--steps", type=int, default=100_000, help="environment steps to train for")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--num-envs", type=int, default=None, help="parallel environments (preset: 8)")
    parser.add_argument("--out", required=True, help="run folder (config.json, progress.csv, checkpoint.pt, tensorboard/)")
    parser.add_argument("--resume", action="store_true", help="continue the run in --out from its last checkpoint")
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help="override a TrainConfig field (JSON value; dotted for nested fields), e.g. --set warmup_steps=500 "
                             "--set flight.max_steps=120 --set actor.hidden=[64,64]")
    parser.add_argument("--quiet", action="store_true", help="no progress output")
    return parser


def _overrides(items: list[str]) -> dict:
    from policies.training.sweep_config import field_problem

    out = {}
    for item in items:
        name, sep, text = item.partition("=")
        problem = field_problem(name) if sep else "no '='"
        if problem:
            raise ValueError(f"--set {item!r}: expected FIELD=VALUE with FIELD a TrainConfig field, dotted for "
                             f"nested ones (flight.max_steps, actor.hidden): {problem}")
        try:
            out[name] = json.loads(text)
        except json.JSONDecodeError:
            out[name] = text
    return out


def main(argv: list[str], prog: str = "hrlsac train") -> int:
    args = build_parser(prog).parse_args(argv)
    from policies.config import TrainConfig
    from policies.evaluation.parallel import quick_evaluation
    from policies.training.sweep_config import build_train_config
    from policies.training.trainer import Trainer

    run_dir = Path(args.out)
    try:
        if args.resume:
            config_path = run_dir / "config.json"
            if not (run_dir / CHECKPOINT).exists() or not config_path.exists():
                raise ValueError(f"--resume: no checkpoint in {run_dir} (expected {CHECKPOINT} and config.json)")
            try:
                config = TrainConfig.from_dict(json.loads(config_path.read_text()))
            except (ValueError, TypeError, KeyError, AttributeError) as exc:  # damaged or hand-edited
                raise ValueError(f"{config_path}: not a readable training config ({type(exc).__name__}: {exc})") \
                    from None
            if args.steps != config.total_steps and "--steps" in argv:
                config = dataclasses.replace(config, total_steps=args.steps)
            trainer = Trainer(config, run_dir, resume=True, evaluate=quick_evaluation)
        else:
            if (run_dir / CHECKPOINT).exists():
                raise ValueError(f"{run_dir} already holds a run; continue it with --resume or choose another --out")
            overrides = _overrides(args.set)
            if args.num_envs is not None:
                overrides["num_envs"] = args.num_envs
            config = build_train_config(args.preset, args.algo, args.seed, args.steps, overrides)
            trainer = Trainer(config, run_dir, evaluate=quick_evaluation)
    except (ValueError, TypeError, OSError) as exc:  # OSError: an --out that cannot be created
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    if not args.quiet:
        print(f"training {config.algo} ({config.preset} preset) for {config.total_steps:,} steps with "
              f"{config.num_envs} environments, seed {config.seed}; run folder {run_dir}"
              + (f" (resumed at step {trainer.step:,})" if args.resume else ""), flush=True)
    # Ctrl-C, and a SIGTERM from a scheduler or `kill`, stop at the next step with a checkpoint. (A job started
    # in the background by a non-interactive shell ignores SIGINT; restore Python's handler for it.)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, _interrupt)
    try:
        path = trainer.run(progress=not args.quiet)
    except KeyboardInterrupt:
        trainer.save()
        print(f"\n{prog}: interrupted at step {trainer.step:,}; checkpoint saved, continue with "
              f"'hrlsac train --out {run_dir} --resume'", file=sys.stderr)
        return 130
    if not args.quiet:
        print(f"done: {trainer.step:,} steps, {trainer.episodes} episodes; checkpoint {path}")
    return 0


def _interrupt(signum, frame) -> None:
    raise KeyboardInterrupt
