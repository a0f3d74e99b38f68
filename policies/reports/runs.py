"""The runs a comparison reads: run folders written by ``hrlsac train`` (``config.json``, ``progress.csv`` and the
``eval_<split>.json`` of ``hrlsac evaluate``), checked on loading, their labels, and the command that trained each.
``compare.py`` compares them; ``markdown.py`` and ``groups.py`` render them."""
from __future__ import annotations

import csv
import json
import math
import shlex
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ALGO_LABELS = {"hrl-sac": "HRL-SAC", "sac": "flat SAC"}
BASELINE_LABELS = {"random": "Random", "expanding_square": "Expanding square", "parallel_track": "Parallel track"}
CURVE_COLUMNS = (("success_rate", "Success rate"), ("mean_return", "Return"),
                 ("mean_coverage", "Coverage ratio"), ("mean_length", "Episode length (steps)"))
TEST_KEYS = {"success_rate": "success_rate", "mean_return": "reward_mean", "mean_coverage": "coverage_mean",
             "mean_length": "length_mean"}
REQUIRED_METRICS = ("episodes", "success_rate", "reward_mean", "reward_std", "coverage_mean", "coverage_std",
                    "length_mean", "length_std")
DEFAULT_EPISODES = 100

class CompareError(ValueError):
    """A problem with the inputs of a comparison; its message is one line meant for the user."""


# ---------------------------------------------------------------------------------------------- loading
@dataclass
class Run:
    """One run folder: its config, its evaluation on the split and its training log."""

    path: Path
    config: dict
    metrics: dict | None = None
    progress: dict[str, np.ndarray] | None = None
    eval_command: str = ""

    @property
    def key(self) -> tuple[str, str]:
        return self.config["algo"], self.config["preset"]


def _read_json(path: Path, what: str) -> dict:
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CompareError(f"{path}: unreadable {what} ({_one_line(exc)})") from None
    if not isinstance(data, dict):
        raise CompareError(f"{path}: unreadable {what} (expected a JSON object)")
    return data


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def read_progress(path: Path) -> dict[str, np.ndarray] | None:
    """The columns of a ``progress.csv`` as float arrays sorted by step; None when the file does not exist."""
    if not path.exists():
        return None
    try:
        with open(path, newline="") as handle:
            reader = csv.DictReader(handle)
            missing = [c for c in ("step", *(name for name, _ in CURVE_COLUMNS)) if c not in (reader.fieldnames or ())]
            if missing:
                raise ValueError(f"missing column(s) {', '.join(missing)}")
            rows = [row for row in reader if row.get("step") not in (None, "")]  # a half-written last line
            data = {name: np.array([float(row[name]) if row.get(name) not in (None, "") else math.nan
                                    for row in rows]) for name in reader.fieldnames}
    except (OSError, UnicodeDecodeError, csv.Error, ValueError) as exc:
        raise CompareError(f"{path}: unreadable CSV ({_one_line(exc)})") from None
    order = np.argsort(data["step"], kind="stable")
    return {name: values[order] for name, values in data.items()}


def load_runs(paths: list, split: str, scenarios: str | None = None) -> list[Run]:
    """Config, existing evaluation (``eval_<split>[_<scenarios>].json``) and training log of each folder (no
    evaluation is run here)."""
    if not paths:
        raise CompareError("no runs given (pass one or more run folders written by hrlsac train)")
    runs, seen = [], set()
    for given in paths:
        path = Path(given)
        if not path.is_dir():
            raise CompareError(f"{path}: no such run folder")
        if path.resolve() in seen:
            raise CompareError(f"{path}: run folder given twice")
        seen.add(path.resolve())
        if not (path / "config.json").is_file():
            raise CompareError(f"{path}: no config.json (not a run folder written by hrlsac train)")
        config = _read_json(path / "config.json", "config.json")
        if config.get("algo") not in ALGO_LABELS or "flight" not in config or "seed" not in config:
            raise CompareError(f"{path / 'config.json'}: not a training config (needs algo, seed and flight)")
        config.setdefault("preset", "default")
        run = Run(path, config, progress=read_progress(path / "progress.csv"))
        eval_path = path / f"eval_{split}{f'_{scenarios}' if scenarios else ''}.json"
        if eval_path.exists():
            run.metrics = _check_metrics(_read_json(eval_path, "evaluation"), eval_path, run, split)
        runs.append(run)
    return runs


def _check_metrics(metrics: dict, path: Path, run: Run, split: str) -> dict:
    missing = [key for key in REQUIRED_METRICS if key not in metrics]
    if missing:
        raise CompareError(f"{path}: not an evaluation of hrlsac evaluate (missing {', '.join(missing)})")
    if metrics.get("split", split) != split:
        raise CompareError(f"{path}: evaluated on split {metrics['split']!r}, not {split!r}")
    if metrics.get("algo", run.config["algo"]) != run.config["algo"]:
        raise CompareError(f"{path}: evaluation of {metrics['algo']}, but config.json says {run.config['algo']}")
    return metrics


def common_flight(runs: list[Run]):
    """The runs' shared FlightSettings; a one-line error naming the first difference otherwise."""
    from missions.mission import FlightSettings

    first = runs[0]
    for run in runs[1:]:
        if run.config["flight"] != first.config["flight"]:
            diff = sorted(k for k in set(first.config["flight"]) | set(run.config["flight"])
                          if first.config["flight"].get(k) != run.config["flight"].get(k))
            detail = ", ".join(f"{k} {first.config['flight'].get(k)} vs {run.config['flight'].get(k)}" for k in diff)
            raise CompareError(f"runs disagree on flight settings: {first.path} and {run.path} differ in {detail}")
    try:
        return FlightSettings(**first.config["flight"])
    except (TypeError, ValueError) as exc:
        raise CompareError(f"{first.path / 'config.json'}: bad flight settings ({_one_line(exc)})") from None


def resolve_episodes(runs: list[Run], episodes: int | None, split: str, evaluate: bool) -> int:
    """The episode count every method is compared on; checks that existing evaluations match it."""
    if episodes is None:
        counts = sorted({int(r.metrics["episodes"]) for r in runs if r.metrics is not None})
        if len(counts) > 1:
            raise CompareError(f"the runs' eval_{split}.json files disagree on the episode count "
                               f"({', '.join(map(str, counts))}); pass --episodes N (with --evaluate to re-evaluate)")
        episodes = counts[0] if counts else DEFAULT_EPISODES
    if episodes < 1:
        raise CompareError(f"--episodes must be >= 1, got {episodes}")
    for run in runs:
        hint = f"run 'hrlsac evaluate {run.path} --split {split} --episodes {episodes}' or pass --evaluate"
        if run.metrics is None and not evaluate:
            raise CompareError(f"{run.path}: no eval_{split}.json ({hint})")
        if run.metrics is not None and int(run.metrics["episodes"]) != episodes and not evaluate:
            raise CompareError(f"{run.path}: eval_{split}.json has {run.metrics['episodes']} episodes, "
                               f"not {episodes} ({hint})")
    return episodes


# ---------------------------------------------------------------------------------------------- commands
def train_command(run: Run) -> str:
    """The ``hrlsac train`` command that makes this run's config.json (nested overrides as a comment)."""
    from policies.config import TrainConfig

    cfg = run.config
    args = ["hrlsac", "train", "--algo", cfg["algo"], "--preset", cfg["preset"],
            "--steps", str(cfg.get("total_steps")), "--seed", str(cfg["seed"])]
    task = cfg.get("task", "SarSearch-v0")  # runs from before the field trained on v0
    if task != TrainConfig.task:
        args += ["--set", f"task={task}"]
    try:
        base = json.loads(json.dumps(TrainConfig.from_preset(cfg["preset"], algo=cfg["algo"], seed=cfg["seed"],
                                                        total_steps=cfg.get("total_steps"), task=task).to_dict()))
    except (TypeError, ValueError):
        base = {}
    notes = []
    for key, value in cfg.items():
        if key in ("algo", "preset", "seed", "total_steps", "task") or base.get(key) == value:
            continue
        if key == "num_envs":
            args += ["--num-envs", str(value)]
        elif isinstance(value, dict) or key not in base:
            old = base.get(key) if isinstance(base.get(key), dict) else {}
            notes += [f"{key}.{k}={json.dumps(v)}" for k, v in value.items() if old.get(k) != v] \
                if isinstance(value, dict) else [f"{key}={json.dumps(value)}"]
        else:
            args += ["--set", f"{key}={json.dumps(value)}"]
    command = shlex.join(args + ["--out", str(run.path)])
    return command + (f"  # config.json also sets {', '.join(notes)} (not settable from the command line)"
                      if notes else "")


def label_of(key: tuple[str, str]) -> str:
    return f"{ALGO_LABELS.get(key[0], key[0])} ({key[1]})"
