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

import json
import os
import shlex
import sys
import time
from pathlib import Path
from typing import TextIO

from policies.evaluation.stats import (  # noqa: F401
    group_stats,
    intervals_overlap,
    pooled_stats,
    t_interval,
    t_quantile_975,
    wilson_interval,
)
from hrlsac_cli.progress import progress_bar
from policies.reports.runs import (  # noqa: F401  (re-exported: the comparison's data model)
    ALGO_LABELS,
    BASELINE_LABELS,
    CURVE_COLUMNS,
    DEFAULT_EPISODES,
    REQUIRED_METRICS,
    TEST_KEYS,
    CompareError,
    Run,
    _check_metrics,
    _one_line,
    _read_json,
    common_flight,
    label_of,
    load_runs,
    read_progress,
    resolve_episodes,
    train_command,
)


# ---------------------------------------------------------------------------------------------- the comparison
def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def compare(runs: list, out, split: str = "test", episodes: int | None = None, evaluate: bool = False,
            command: str | None = None, progress: TextIO | bool | None = True, streams: int = 5,
            generator=None, scenarios: str | None = None, scripted: list[str] | None = None) -> dict:
    """Compare run folders and the scripted baselines on ``split``; writes the report and figures into ``out``.

    Missing (or differently sized) evaluations are computed with ``evaluate=True`` and saved as
    ``RUN/eval_<split>.json``; without it they are a :class:`CompareError`. ``episodes`` None takes the count of
    the runs' evaluation files (100 when there are none). ``progress``: True shows a progress bar of the episodes
    to fly (``policies.reports.progress``) and a line per run and scripted searcher on stderr, a stream shows them
    there, None/False is silent. ``command`` is the command line recorded in the report
    (default: reconstructed). Returns the summary written to ``out/summary.json`` plus the paths of the files.
    SarSearch-v1 runs also get the rows of ``policies.reports.groups`` (scripted searchers over ``streams``
    detection streams, constant goals, IQM, P(found by t)); ``generator`` (a GeneratorConfig) with ``scenarios``
    (the name ``hrlsac evaluate --generator`` gave the eval files) compares on that distribution instead;
    ``scripted`` names the scripted searchers to fly (default: all of ``missions.searchers.SEARCHERS``).
    """
    from policies.env.baselines_v0 import BASELINES_V0
    from missions.searchers import SEARCHERS
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
    to_evaluate = [run for run in loaded if run.metrics is None or int(run.metrics["episodes"]) != episodes]
    flown = (len(to_evaluate) + (len(scripted or SEARCHERS) * streams if task == "SarSearch-v1" else
                                 len(BASELINES_V0))) * episodes
    with progress_bar(flown, "episode", "comparing", enabled=progress is not None, stream=progress) as bar:
        for i, run in enumerate(loaded, 1):
            what = (f"[run {i}/{len(loaded)}] {run.path}: {run.config['algo']} ({run.config['preset']}) "
                    f"seed {run.config['seed']}")
            run.eval_command = shlex.join(["hrlsac", "evaluate", str(run.path), "--split", split,
                                           "--episodes", str(episodes)])
            if run not in to_evaluate:
                eval_file = f"eval_{split}{f'_{scenarios}' if scenarios else ''}.json"
                bar.note(f"{what}: {eval_file}, success {run.metrics['success_rate']:.1%}")
                continue
            bar.set_description(f"evaluating run {i}/{len(loaded)}", refresh=False)
            run.metrics = _evaluate(run, split, episodes, bar.follow())
            bar.note(f"{what}: evaluated on {split} ({episodes} episodes), success {run.metrics['success_rate']:.1%}")
        baselines, scripted_rows = {}, None
        environment = {"generator": generator} if generator is not None else {}
        if task == "SarSearch-v1":
            scripted_rows, baselines = compare_groups.scripted_rows(task, split, episodes, flight, streams,
                                                                    environment, bar, scripted)
        for i, name in enumerate(BASELINES_V0 if task == "SarSearch-v0" else (), 1):
            bar.set_description(name, refresh=False)
            baselines[name] = _run_baseline(name, split, episodes, flight, bar.follow())
            bar.note(f"[baseline {i}/{len(BASELINES_V0)}] {name} on {split} ({episodes} episodes): success "
                      f"{baselines[name]['success_rate']:.1%}")

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
    from policies.reports.markdown import plot_boxplots, plot_training_curves, render_report

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


def _evaluate(run: Run, split: str, episodes: int, on_progress) -> dict:
    from policies.evaluation.parallel import evaluate_checkpoint

    try:
        metrics = evaluate_checkpoint(run.path, split, episodes, on_progress=on_progress)
    except (FileNotFoundError, ValueError, KeyError, RuntimeError) as exc:
        raise CompareError(f"{run.path}: cannot evaluate ({_one_line(exc)})") from None
    _write_atomic(run.path / f"eval_{split}.json", json.dumps(metrics, indent=2))
    return metrics


def _run_baseline(name: str, split: str, episodes: int, flight, on_progress) -> dict:
    from policies.evaluation.baselines import run_baseline

    return run_baseline(name, split, episodes, flight, on_progress=on_progress)


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
