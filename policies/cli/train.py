"""``hrlsac train``: HRL-SAC or flat SAC on SarSearch-v1 or v0 (--set task=...) into a run folder (resumable).

The settings come from the options (a preset plus ``--set`` overrides) or, with ``--sweep FILE --run NAME``, from
one run of a sweep file: the config ``hrlsac sweep`` would train for that run, into the folder it would use, without
Ray. That is how one run of a published comparison is trained again, e.g. the shipped HRL-SAC policy:
``hrlsac train --sweep docs/results/hrl-sac.sweep.yaml --run hrl-sac-default-seed0``.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import signal
import sys
from pathlib import Path

from hrlsac_cli.help_format import HelpFormatter
from policies.checkpoint import CHECKPOINT

# The options a sweep file's run decides; given beside --sweep they would be ignored, so they are refused.
SWEEP_DECIDES = {"algo": "--algo", "preset": "--preset", "steps": "--steps", "seed": "--seed",
                 "num_envs": "--num-envs", "set": "--set"}
DEFAULTS = {"algo": "hrl-sac", "preset": "default", "steps": 100_000, "seed": 0, "num_envs": None, "set": []}


def build_parser(prog: str) -> argparse.ArgumentParser:
    # The options of SWEEP_DECIDES default to None here (DEFAULTS fills them in, the help texts name them), so
    # that main can tell an option given on the command line from its default.
    parser = argparse.ArgumentParser(prog=prog, description=__doc__.split(":", 1)[1].split("\n\n")[0].strip(),
                                     formatter_class=HelpFormatter)
    parser.add_argument("--algo", choices=["hrl-sac", "sac"], help="algorithm (default: hrl-sac)")
    parser.add_argument("--preset", choices=["default", "paper"], help="network sizes and settings (default: default)")
    parser.add_argument("--steps", type=int, help="environment steps to train for (default: 100000)")
    parser.add_argument("--seed", type=int, help="seed of every random draw (default: 0)")
    parser.add_argument("--num-envs", type=int, help="parallel environments (default: the preset's, 8)")
    parser.add_argument("--out", help="run folder (config.json, progress.csv, checkpoint.pt, tensorboard/); with "
                                      "--sweep, default: the run's folder in the sweep's 'out'")
    parser.add_argument("--resume", action="store_true", help="continue the run in --out from its last checkpoint")
    parser.add_argument("--set", action="append", metavar="FIELD=VALUE",
                        help="override a TrainConfig field (JSON value; dotted for nested fields), e.g. "
                             "--set warmup_steps=500 --set flight.max_steps=120 --set actor.hidden=[64,64]")
    parser.add_argument("--sweep", metavar="FILE", help="take the settings of one run of this sweep file "
                                                        "(docs/scaling.md) instead of the options above")
    parser.add_argument("--run", metavar="NAME", help="with --sweep: the run to train, e.g. hrl-sac-default-seed0 "
                                                      "('hrlsac sweep FILE --dry-run' lists them)")
    parser.add_argument("--quiet", action="store_true", help="no progress output")
    return parser


def _sweep_run(args: argparse.Namespace):
    """The RunSpec that --sweep and --run name; ValueError (one line) for a missing, unknown or ambiguous run."""
    from policies.training.sweep_config import load_sweep

    given = [option for dest, option in SWEEP_DECIDES.items() if getattr(args, dest) is not None]
    if given:
        raise ValueError(f"{', '.join(given)}: set by the sweep file's run with --sweep; change the sweep file, "
                         "or drop --sweep to train from the options")
    sweep = load_sweep(args.sweep)
    names = [spec.name for spec in sweep.runs]
    if args.run is None and len(names) == 1:
        return sweep.runs[0]
    if args.run not in names:
        listed = ", ".join(names[:6]) + (f", ... ({len(names)} runs)" if len(names) > 6 else "")
        what = "give --run NAME" if args.run is None else f"--run {args.run!r} is not one of its runs"
        raise ValueError(f"{args.sweep}: {what}; the sweep's runs: {listed}")
    return sweep.runs[names.index(args.run)]


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
    from policies.training.sweep import config_difference
    from policies.training.sweep_config import build_train_config
    from policies.training.trainer import Trainer

    try:
        spec = _sweep_run(args) if args.sweep else None
        if args.run is not None and spec is None:
            raise ValueError("--run names a run of a sweep file: give --sweep FILE too")
        if args.out is None and spec is None:
            raise ValueError("--out is required: the run folder to write (or --sweep FILE --run NAME)")
        run_dir = Path(args.out) if args.out is not None else spec.folder
        if args.resume:
            config_path = run_dir / "config.json"
            if not (run_dir / CHECKPOINT).exists() or not config_path.exists():
                raise ValueError(f"--resume: no checkpoint in {run_dir} (expected {CHECKPOINT} and config.json)")
            try:
                config = TrainConfig.from_dict(json.loads(config_path.read_text()))
            except (ValueError, TypeError, KeyError, AttributeError) as exc:  # damaged or hand-edited
                raise ValueError(f"{config_path}: not a readable training config ({type(exc).__name__}: {exc})") \
                    from None
            if spec is not None:  # as hrlsac sweep resumes it: the same settings, extended to the sweep's steps
                difference = config_difference(json.loads(config_path.read_text()), spec.config)
                if difference:
                    raise ValueError(f"--resume: {run_dir} was trained with {difference} (run {spec.name}); "
                                     "restore the sweep file, or resume without --sweep")
                config = dataclasses.replace(config, total_steps=spec.config.total_steps)
            elif args.steps is not None and args.steps != config.total_steps:
                config = dataclasses.replace(config, total_steps=args.steps)
            trainer = Trainer(config, run_dir, resume=True, evaluate=quick_evaluation)
        else:
            if (run_dir / CHECKPOINT).exists():
                raise ValueError(f"{run_dir} already holds a run; continue it with --resume or choose another --out")
            if spec is not None:
                config = spec.config
            else:
                options = {dest: DEFAULTS[dest] if getattr(args, dest) is None else getattr(args, dest)
                           for dest in SWEEP_DECIDES}
                overrides = _overrides(options["set"])
                if options["num_envs"] is not None:
                    overrides["num_envs"] = options["num_envs"]
                config = build_train_config(options["preset"], options["algo"], options["seed"], options["steps"],
                                            overrides)
            trainer = Trainer(config, run_dir, evaluate=quick_evaluation)
    except (ValueError, TypeError, OSError) as exc:  # OSError: an --out that cannot be created
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    if not args.quiet:
        source = f"run {spec.name} of {args.sweep}, " if spec is not None else ""
        print(f"training {source}{config.algo} ({config.preset} preset) for {config.total_steps:,} steps with "
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
