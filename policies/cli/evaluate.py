"""``hrlsac evaluate``: the paper's metrics of a trained run on a scenario split, or on your own scenarios, as JSON.

Scenarios: the first --episodes of a generator split (default), a folder of mission files (``--missions DIR``:
every ``*.yaml`` in it, in name order; episode i flies mission i modulo their number), or a generator config file
(``--generator FILE``: a YAML mapping of ``missions.generator.GeneratorConfig`` fields, e.g. ``area_size_m: 2000``;
the split's seeds drawn from that distribution). Missions are flown with the policy's training flight settings,
and their flight blocks must match them.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
from pathlib import Path

from hrlsac_cli.help_format import HelpFormatter
from missions.generator import SPLITS
from simulation.worker_pool import WorkerPoolError, add_pool_arguments, pool_from_arguments


def main(argv: list[str], prog: str = "hrlsac evaluate") -> int:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__.split(":", 1)[1].strip(),
                                     formatter_class=HelpFormatter)
    parser.add_argument("run", help="run folder (or checkpoint file) written by hrlsac train")
    parser.add_argument("--split", choices=SPLITS, default="test")
    parser.add_argument("--episodes", type=int, default=None,
                        help="one episode on each of the first N scenarios (default 100; with --missions, one each)")
    scenarios = parser.add_mutually_exclusive_group()
    scenarios.add_argument("--missions", default=None, help="folder of mission files to evaluate on instead")
    scenarios.add_argument("--generator", default=None, help="generator config file (YAML) to draw the split from")
    parser.add_argument("--constant-goal", default=None, help="HRL-SAC: fly this goal (a GOAL_NAMES name) at every "
                                                              "decision with the learned low level")
    parser.add_argument("--flight-rules", action="store_true",
                        help="fly with the mission runner's rules instead of training's: a ReturnToBase decision ends "
                             "the search (RTL) and so does the pilot's bingo failsafe (what a real flight does)")
    parser.add_argument("--out", default=None,
                        help="metrics file (default: RUN/eval_SPLIT[_NAME][_flight][_goal-GOAL].json)")
    parser.add_argument("--quiet", action="store_true", help="no progress output")
    add_pool_arguments(parser)
    args = parser.parse_args(argv)
    if args.episodes is not None and args.episodes < 1:
        print(f"{prog}: error: --episodes must be >= 1, got {args.episodes}", file=sys.stderr)
        return 2
    from policies.evaluation.parallel import evaluate_checkpoint
    from hrlsac_cli.progress import progress_bar

    try:
        environment, name, count = user_scenarios(args.missions, args.generator, args.run)
        episodes = args.episodes or count or 100
        goal = goal_index(args.constant_goal)
        pool = pool_from_arguments(args)
        if (pool.workers > 1 or pool.uses_ray) and not args.quiet:
            print(f"evaluating {episodes} episodes on {pool.describe()}", file=sys.stderr, flush=True)
        with progress_bar(episodes, "episode", "evaluating", enabled=not args.quiet) as bar:
            metrics = evaluate_checkpoint(args.run, args.split, episodes, pool, bar.advance_to, environment, goal,
                                          flight_rules=args.flight_rules)
    except (FileNotFoundError, ValueError, KeyError, WorkerPoolError) as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    metrics["scenarios"] = name or f"generator split {args.split}"
    run = Path(args.run)
    suffix = ((f"_{name}" if name else "") + ("_flight" if args.flight_rules else "")
              + (f"_goal-{args.constant_goal}" if args.constant_goal else ""))
    out = Path(args.out) if args.out else (run if run.is_dir() else run.parent) / f"eval_{args.split}{suffix}.json"
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(json.dumps(metrics, indent=2))
    os.replace(tmp, out)
    low, high = metrics["success_ci95"]
    print(f"{metrics['algo']} seed {metrics['seed']} on {metrics['scenarios']} ({episodes} episodes): success "
          f"{metrics['success_rate']:.1%} [{low:.1%}, {high:.1%}], ran dry {metrics['ran_dry_rate']:.1%}, reward "
          f"{metrics['reward_mean']:.1f}, coverage {metrics['coverage_mean']:.1%}, length {metrics['length_mean']:.0f}"
          + (f", sub-goal reachability {metrics['subgoal_reachability']:.1%}"
             if metrics["subgoal_reachability"] is not None else ""))
    print(f"written {out}")
    return 0


def goal_index(name: str | None) -> int | None:
    """The index of a goal named on the command line (ValueError naming the goals otherwise)."""
    from missions.goals import GOAL_NAMES

    if name is None:
        return None
    if name not in GOAL_NAMES:
        raise ValueError(f"--constant-goal must be one of {', '.join(GOAL_NAMES)}, got {name!r}")
    return GOAL_NAMES.index(name)


def user_scenarios(missions: str | None, generator: str | None, run: str) -> tuple[dict, str | None, int | None]:
    """``SarSearchConfig`` fields for the scenarios asked for, a short name for the metrics file, and how many
    scenarios there are (None for a generator)."""
    if missions is not None:
        from missions.mission_file import load_mission

        folder = Path(missions)
        files = sorted(folder.glob("*.yaml")) if folder.is_dir() else []
        if not files:
            raise ValueError(f"--missions {folder}: no mission files (*.yaml) in that folder")
        loaded = [load_mission(path) for path in files]
        _check_flight(loaded, files, run)
        return {"scenarios": tuple(m.scenario for m in loaded)}, f"missions-{folder.name}", len(loaded)
    if generator is not None:
        config = read_generator_config(generator, run_config(run).task)
        return {"generator": config}, f"generator-{Path(generator).stem}", None
    return {}, None, None


def run_config(run: str):
    """The ``TrainConfig`` of a run folder (its config.json) or checkpoint file."""
    from policies.checkpoint import checkpoint_file, load_checkpoint_state
    from policies.config import TrainConfig

    folder = Path(run)
    if folder.is_dir() and (folder / "config.json").is_file():
        return TrainConfig.from_dict(json.loads((folder / "config.json").read_text()))
    path = checkpoint_file(run)
    return TrainConfig.from_dict(load_checkpoint_state(path, path)["config"])


def read_generator_config(path: str, task: str = "SarSearch-v1"):
    """A ``GeneratorConfig`` from a YAML mapping of its fields, over the task's own distribution (SarSearch-v1's
    decoys, endurance and forecast error stay unless the file sets them); one-line errors name the file and the
    field."""
    from missions.generator import TASK_V1, GeneratorConfig
    from missions.mission_file import MissionFileError, _parse_yaml

    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise ValueError(f"--generator {path}: cannot read ({exc.strerror or exc})") from None
    try:
        data = _parse_yaml(text, path)
    except MissionFileError as exc:
        raise ValueError(str(exc)) from None
    names = [f.name for f in dataclasses.fields(GeneratorConfig)]
    if not isinstance(data, dict) or any(key not in names for key in data):
        unknown = [key for key in data if key not in names] if isinstance(data, dict) else []
        raise ValueError(f"{path}: a generator config is a mapping of GeneratorConfig fields ({', '.join(names)})"
                         + (f"; unknown: {', '.join(map(str, unknown))}" if unknown else ""))
    if "primary_categories" in data:
        data["primary_categories"] = tuple(data["primary_categories"])
    base = TASK_V1 if task == "SarSearch-v1" else GeneratorConfig()
    try:
        return dataclasses.replace(base, **data)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: {exc}") from None


def _check_flight(loaded: list, files: list[Path], run: str) -> None:
    flight = run_config(run).flight
    for mission, file in zip(loaded, files):
        if mission.flight != flight:
            raise ValueError(f"{file}: its flight settings differ from the policy's training flight settings "
                             f"({dataclasses.asdict(flight)})")
