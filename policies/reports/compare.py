"""Comparing trained runs (HRL-SAC, flat SAC) with the scripted baselines: statistics, a markdown report, figures.

:func:`compare` reads run folders written by ``hrlsac train`` (``config.json``, ``progress.csv`` and the
``eval_<split>.json`` of ``hrlsac evaluate``), groups them by (algo, preset), evaluates the scripted baselines on
the same scenarios with the same flight settings, and writes ``report.md``, ``summary.json``,
``training_curves.png`` and ``boxplots.png`` into the output folder.

Statistics of a group of seeds: the per-seed success rates give a mean, a sample standard deviation and a 95 %
Student-t interval across seeds (clipped to [0, 1]); all episodes pooled give a success rate with a Wilson
interval, reward / coverage / length means and standard deviations (population, as the evaluation's), the median
time to first detection and the median steps to success.
"""
from __future__ import annotations

import csv
import json
import math
import os
import shlex
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np

from policies.evaluation.stats import (  # noqa: F401
    group_stats,
    intervals_overlap,
    pooled_stats,
    t_interval,
    t_quantile_975,
    wilson_interval,
)

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


# ---------------------------------------------------------------------------------------------- the comparison
def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def _say(stream: TextIO | None, text: str, end: str = "\n") -> None:
    if stream is not None:
        print(text, end=end, file=stream, flush=True)


def label_of(key: tuple[str, str]) -> str:
    return f"{ALGO_LABELS.get(key[0], key[0])} ({key[1]})"


def compare(runs: list, out, split: str = "test", episodes: int | None = None, evaluate: bool = False,
            command: str | None = None, progress: TextIO | bool | None = True, streams: int = 5,
            generator=None, scenarios: str | None = None) -> dict:
    """Compare run folders and the scripted baselines on ``split``; writes the report and figures into ``out``.

    Missing (or differently sized) evaluations are computed with ``evaluate=True`` and saved as
    ``RUN/eval_<split>.json``; without it they are a :class:`CompareError`. ``episodes`` None takes the count of
    the runs' evaluation files (100 when there are none). ``progress``: True prints one line per run and baseline
    to stderr, a stream prints there, None/False is silent. ``command`` is the command line recorded in the report
    (default: reconstructed). Returns the summary written to ``out/summary.json`` plus the paths of the files.
    SarSearch-v1 runs also get the rows of ``policies.reports.groups`` (scripted searchers over ``streams``
    detection streams, constant goals, IQM, P(found by t)); ``generator`` (a GeneratorConfig) with ``scenarios``
    (the name ``hrlsac evaluate --generator`` gave the eval files) compares on that distribution instead.
    """
    from policies.env.baselines_v0 import BASELINES_V0
    from policies.reports import groups as compare_groups

    progress = sys.stderr if progress is True else (progress or None)
    loaded = load_runs(list(runs), split, scenarios)
    flight = common_flight(loaded)
    task = compare_groups.check_task(loaded)
    if (generator is not None or scenarios) and (evaluate or task != "SarSearch-v1"):
        raise CompareError("other scenarios than the split's are compared from existing SarSearch-v1 evaluations "
                           "(hrlsac evaluate --generator FILE), without --evaluate")
    episodes = resolve_episodes(loaded, episodes, split, evaluate)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise CompareError(f"--out {out}: exists and is not a folder")
    for i, run in enumerate(loaded, 1):
        what = (f"[run {i}/{len(loaded)}] {run.path}: {run.config['algo']} ({run.config['preset']}) "
                f"seed {run.config['seed']}")
        run.eval_command = shlex.join(["hrlsac", "evaluate", str(run.path), "--split", split,
                                       "--episodes", str(episodes)])
        if run.metrics is not None and int(run.metrics["episodes"]) == episodes:
            _say(progress, f"{what}: eval_{split}.json, success {run.metrics['success_rate']:.1%}")
            continue
        _say(progress, f"{what}: evaluating on {split} ({episodes} episodes) ... ", end="")
        started = time.perf_counter()
        run.metrics = _evaluate(run, split, episodes)
        _say(progress, f"success {run.metrics['success_rate']:.1%} ({time.perf_counter() - started:.1f} s)")
    baselines, scripted_rows = {}, None
    environment = {"generator": generator} if generator is not None else {}
    if task == "SarSearch-v1":
        scripted_rows, baselines = compare_groups.scripted_rows(task, split, episodes, flight, streams, environment,
                                                                progress)
    for i, name in enumerate(BASELINES_V0 if task == "SarSearch-v0" else (), 1):
        _say(progress, f"[baseline {i}/{len(BASELINES_V0)}] {name} on {split} ({episodes} episodes) ... ", end="")
        started = time.perf_counter()
        baselines[name] = _run_baseline(name, split, episodes, flight)
        _say(progress, f"success {baselines[name]['success_rate']:.1%} ({time.perf_counter() - started:.1f} s)")

    groups: dict[tuple[str, str], list[Run]] = {}
    for run in sorted(loaded, key=lambda r: (list(ALGO_LABELS).index(r.key[0]), r.key[1], r.config["seed"])):
        groups.setdefault(run.key, []).append(run)
    if command is None:
        command = shlex.join(["hrlsac", "compare", *map(str, runs), "--out", str(out), "--split", split,
                              "--episodes", str(episodes)])
    summary = {
        "split": split, "episodes": episodes, "flight": loaded[0].config["flight"], "command": command,
        "generated_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "groups": [{"label": label_of(key), "algo": key[0], "preset": key[1], "runs": [str(r.path) for r in members],
                    "seeds": [r.config["seed"] for r in members], **group_stats([r.metrics for r in members])}
                   for key, members in groups.items()],
        "baselines": [{"label": BASELINE_LABELS.get(name, name), "baseline": name,
                       **pooled_stats([metrics])} for name, metrics in baselines.items()],
    }
    summary["verdicts"] = verdicts(summary["groups"])
    summary["task"] = task
    out.mkdir(parents=True, exist_ok=True)
    from policies.reports.markdown import (  # it imports us
        plot_boxplots,
        plot_training_curves,
        render_report,
    )

    files = {"report": out / "report.md", "summary": out / "summary.json",
             "training_curves": out / "training_curves.png", "boxplots": out / "boxplots.png"}
    if scripted_rows is not None:
        for row, members in zip(summary["groups"], groups.values()):
            row["metrics"] = [r.metrics for r in members]
        hrl_runs = [r for r in loaded if r.config["algo"] == "hrl-sac"]
        summary["baselines"] = scripted_rows
        summary["constant_goals"] = compare_groups.constant_goal_rows(hrl_runs, split, scenarios)
        rows = summary["groups"] + summary["constant_goals"] + scripted_rows
        summary["strata"] = compare_groups.add_aggregates(rows, split, episodes, flight, task, environment)
        hrl = next((row for row in summary["groups"] if row["algo"] == "hrl-sac"), None)
        summary["task_verdicts"] = compare_groups.verdicts_against(hrl, [r for r in rows if r is not hrl]) \
            if hrl else []
        files["found_by"] = out / "found_by.png"
        compare_groups.plot_found_by(rows, files["found_by"])
        summary["scenarios"] = scenarios or f"the first {episodes} scenarios of the {split} split"
    plot_training_curves(groups, summary, files["training_curves"])
    plot_boxplots(groups, baselines, summary, files["boxplots"])
    for row in summary["groups"] + summary.get("constant_goals", []) + summary["baselines"]:
        row.pop("metrics", None)  # the per-episode lists stay in the runs' evaluation files
    _write_atomic(files["summary"], json.dumps(summary, indent=2))
    _write_atomic(files["report"], render_report(summary, groups, flight))
    summary["files"] = {name: str(path) for name, path in files.items()}
    return summary


def _evaluate(run: Run, split: str, episodes: int) -> dict:
    from policies.evaluation.episodes import evaluate_checkpoint

    try:
        metrics = evaluate_checkpoint(run.path, split, episodes)
    except (FileNotFoundError, ValueError, KeyError, RuntimeError) as exc:
        raise CompareError(f"{run.path}: cannot evaluate ({_one_line(exc)})") from None
    _write_atomic(run.path / f"eval_{split}.json", json.dumps(metrics, indent=2))
    return metrics


def _run_baseline(name: str, split: str, episodes: int, flight) -> dict:
    from policies.evaluation.baselines import run_baseline

    return run_baseline(name, split, episodes, flight)


def verdicts(groups: list[dict]) -> list[dict]:
    """HRL-SAC against flat SAC of the same preset: do their 95 % intervals overlap (across seeds; pooled)?"""
    by_key = {(g["algo"], g["preset"]): g for g in groups}
    found = []
    for (algo, preset), hrl in by_key.items():
        sac = by_key.get(("sac", preset))
        if algo != "hrl-sac" or sac is None:
            continue
        seeds_ok = hrl["success_t95"] is not None and sac["success_t95"] is not None
        found.append({
            "preset": preset, "hrl": hrl["label"], "sac": sac["label"],
            "hrl_success_mean": hrl["success_mean"], "sac_success_mean": sac["success_mean"],
            "seed_intervals_overlap": intervals_overlap(hrl["success_t95"], sac["success_t95"]) if seeds_ok else None,
            "pooled_intervals_overlap": intervals_overlap(hrl["wilson95"], sac["wilson95"]),
            "hrl_above_with_non_overlapping_intervals":
                bool(seeds_ok and hrl["success_t95"][0] > sac["success_t95"][1]),
        })
    return found


# ---------------------------------------------------------------------------------------------- the report
