"""The SarSearch-v1 rows of ``hrlsac compare`` beyond the run folders: the scripted searchers over several
detection streams, every constant goal under each HRL-SAC run's learned low level, the rliable-style aggregates
(``policies.evaluation.aggregate``), P(found by t), and the verdicts of HRL-SAC against every other row.

* **scripted searchers** (``missions.searchers``, the settings tuned on val): each flies the same scenarios once
  per stream k = 0 .. streams-1 (the same scenarios with other detection draws, ``episode_batch``'s ``stream``):
  its runs, as the seeds are a learned method's;
* **constant goals**: ``hrlsac evaluate RUN --constant-goal GOAL`` writes ``eval_<split>[_<scenarios>]_goal-<GOAL>
  .json``; a goal's row is its files across the HRL-SAC runs (left out when some are missing);
* **verdicts**: HRL-SAC above a row when the lower end of its 95 % interval across seeds lies above the upper end
  of that row's (Student-t across runs; the same test on the stratified-bootstrap interval of the IQM).
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Sequence

import numpy as np

from missions.goals import GOAL_NAMES
from policies.evaluation.aggregate import STRATA, aggregate, strata_of
from policies.evaluation.episodes import FOUND_BY_S, episode_batch
from policies.evaluation.stats import group_stats, intervals_overlap
from policies.reports.figures import colour, new_figure, save_figure
from hrlsac_cli.progress import ProgressBar
from policies.reports.runs import CompareError, Run

SCRIPTED_LABELS = {"random": "Random", "expanding_square": "Expanding square (bounded, repeated)",
                   "parallel_track": "Parallel track (bounded, repeated)", "greedy_bayes": "Greedy Bayesian",
                   "lookahead_bayes": "Greedy Bayesian with lookahead"}


def scripted_rows(task: str, split: str, episodes: int, flight, streams: int, environment: dict, bar: ProgressBar,
                  names: Sequence[str] | None = None) -> tuple[list[dict], dict[str, dict]]:
    """Each scripted searcher's row (``names``, default all) over ``streams`` detection streams, and its first
    stream's metrics (figures); ``bar`` (``policies.reports.progress``) follows their episodes."""
    from missions.searchers import SEARCHERS
    from policies.evaluation.baselines import run_baseline

    rows, first = [], {}
    for name in names or SEARCHERS:
        runs = []
        for stream in range(streams):
            bar.set_description(f"{name}, stream {stream + 1}/{streams}", refresh=False)
            runs.append(run_baseline(name, split, episodes, flight, task=task, stream=stream,
                                     on_progress=bar.follow(), **environment))
            bar.note(f"[scripted] {name}, stream {stream + 1}/{streams}: success {runs[-1]['success_rate']:.1%}")
        first[name] = runs[0]
        rows.append({"label": SCRIPTED_LABELS.get(name, name), "baseline": name, "kind": "scripted",
                     **group_stats(runs), "metrics": runs})
    return rows, first


def constant_goal_rows(hrl_runs: list[Run], split: str, scenarios: str | None) -> list[dict]:
    """One row per goal whose constant-goal evaluation exists for every HRL-SAC run."""
    rows = []
    suffix = f"_{scenarios}" if scenarios else ""
    for goal in GOAL_NAMES:
        files = [run.path / f"eval_{split}{suffix}_goal-{goal}.json" for run in hrl_runs]
        if not hrl_runs or not all(f.exists() for f in files):
            continue
        metrics = [json.loads(f.read_text()) for f in files]
        rows.append({"label": f"HRL-SAC's low level, always {goal}", "kind": "constant goal", "goal": goal,
                     **group_stats(metrics), "metrics": metrics})
    return rows


def add_aggregates(rows: list[dict], split: str, episodes: int, flight, task: str, environment: dict) -> list[str]:
    """Add each row's IQM / mean aggregate (runs x condition strata) and mean P(found by t); returns strata names."""
    scenarios = episode_batch(split, episodes, flight, goal_conditioned=False, task=task, **environment).scenarios
    strata, names = strata_of(scenarios)
    for row in rows:
        metrics = row["metrics"]
        if any("per_episode" not in m for m in metrics):
            continue
        successes = [np.asarray(m["per_episode"]["success"], dtype=bool) for m in metrics]
        row["aggregate"] = aggregate(successes, strata, len(names))
        row["found_by"] = {key: float(np.mean([m["found_by"][key] for m in metrics]))
                           for key in metrics[0].get("found_by", {})}
        for key in ("ran_dry_rate", "returned_rate"):
            row[key] = float(np.mean([m.get(key, 0.0) for m in metrics]))
    return names


def verdicts_against(hrl: dict, others: list[dict]) -> list[dict]:
    """HRL-SAC's row against each other row: above with non-overlapping intervals (across seeds; IQM)?"""
    found = []
    for other in others:
        ok = hrl.get("success_t95") is not None and other.get("success_t95") is not None
        iqm = "aggregate" in hrl and "aggregate" in other
        found.append({
            "against": other["label"], "hrl_success_mean": hrl["success_mean"],
            "other_success_mean": other["success_mean"],
            "above_non_overlapping_seeds": bool(ok and hrl["success_t95"][0] > other["success_t95"][1]),
            "seed_intervals_overlap": intervals_overlap(hrl["success_t95"], other["success_t95"]) if ok else None,
            "above_non_overlapping_iqm": bool(iqm and hrl["aggregate"]["iqm_ci95"][0]
                                              > other["aggregate"]["iqm_ci95"][1]),
            "hrl_reward_mean": hrl.get("reward_seed_mean"), "other_reward_mean": other.get("reward_seed_mean"),
            "reward_above_non_overlapping_seeds": bool(hrl.get("reward_t95") and other.get("reward_t95")
                                                       and hrl["reward_t95"][0] > other["reward_t95"][1]),
        })
    return found


def _pct(x) -> str:
    return "—" if x is None else f"{100 * x:.1f} %"


def _num(x) -> str:
    return "—" if x is None else f"{x:.1f}"


def _reward(row: dict) -> str:
    interval = row.get("reward_t95")
    return _num(row.get("reward_seed_mean")) + ("" if not interval else f" [{interval[0]:.1f}, {interval[1]:.1f}]")


def _ci(interval) -> str:
    return "—" if interval is None else f"[{100 * interval[0]:.1f}, {100 * interval[1]:.1f}]"


def render_task_table(summary: dict) -> list[str]:
    """The SarSearch-v1 section of the report: the headline table, P(found by t), the verdicts."""
    rows = summary["groups"] + summary.get("constant_goals", []) + summary["baselines"]
    times = [f"{t:g}s" for t in FOUND_BY_S]
    out = ["## SarSearch-v1: every method on the same scenarios", "",
           f"Runs: training seeds (learned) or detection streams (scripted: the same {summary['episodes']} scenarios "
           "with other detection draws). IQM: interquartile mean over runs x the 12 condition strata "
           f"({' x '.join(STRATA)}), with a stratified-bootstrap 95 % interval (policies/evaluation/aggregate.py).", "",
           "| method | runs | success (mean ± std, t 95 %) | IQM [bootstrap 95 %] | pooled [Wilson 95 %] | ran dry | "
           "returned | reward (mean, t 95 %) | collision | out of bounds |",
           "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        aggregate_ = r.get("aggregate")
        iqm = f"{_pct(aggregate_['iqm'])} {_ci(aggregate_['iqm_ci95'])}" if aggregate_ else "—"
        spread = f"{100 * r['success_mean']:.1f} ± {100 * (r['success_std'] or 0.0):.1f} % {_ci(r['success_t95'])}"
        out.append(f"| {r['label']} | {r['seeds']} | {spread} | {iqm} | {_pct(r['success'])} {_ci(r['wilson95'])} | "
                   f"{_pct(r.get('ran_dry_rate'))} | {_pct(r.get('returned_rate'))} | {_reward(r)} | "
                   f"{_pct(r['collision_rate'])} | {_pct(r['out_of_bounds_rate'])} |")
    out += ["", "P(found by t): the share of all episodes (not only the successful ones) in which the victim had been "
                "confirmed and reached by t seconds of flight (mean over runs).", "",
            "| method | " + " | ".join(times) + " |", "|---|" + "---|" * len(times)]
    out += [f"| {r['label']} | " + " | ".join(_pct(r.get("found_by", {}).get(t)) for t in times) + " |" for r in rows]
    out += ["", "![P(found by t)](found_by.png)", ""]
    for verdict in summary.get("task_verdicts", []):
        word = ("**above, with non-overlapping 95 % intervals across seeds**" if verdict["above_non_overlapping_seeds"]
                else "not above with non-overlapping intervals across seeds")
        reward = ("above" if verdict.get("reward_above_non_overlapping_seeds") else "not above")
        out.append(f"- HRL-SAC ({_pct(verdict['hrl_success_mean'])}) vs {verdict['against']} "
                   f"({_pct(verdict['other_success_mean'])}): {word}; IQM intervals "
                   f"{'separate' if verdict['above_non_overlapping_iqm'] else 'not separate above'}; reward "
                   f"{_num(verdict.get('hrl_reward_mean'))} vs {_num(verdict.get('other_reward_mean'))}: {reward} "
                   f"with non-overlapping intervals.")
    return out + [""]


def plot_found_by(rows: list[dict], path: Path, times=FOUND_BY_S) -> None:
    """P(found by t) per row, from each run's per-episode successes and lengths (seconds = steps x period)."""
    fig = new_figure(9, 5.5)
    ax = fig.subplots()
    grid = np.arange(0, max(times) + 181, 10)
    for i, row in enumerate(rows):
        if "aggregate" not in row:
            continue
        curves = []
        for m in row["metrics"]:
            success = np.asarray(m["per_episode"]["success"], dtype=bool)
            length = np.asarray(m["per_episode"]["length"], dtype=np.float64)
            curves.append([(success & (length <= t)).mean() for t in grid])
        ax.plot(grid, np.mean(curves, axis=0), label=row["label"], color=colour(i),
                linestyle="--" if row.get("kind") == "scripted" else ":" if row.get("kind") == "constant goal" else "-")
    ax.set_xlabel("flight time t (s)")
    ax.set_ylabel("P(victim confirmed and reached by t)")
    ax.set_ylim(0, 1)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left")
    save_figure(fig, path)


def check_task(runs: list[Run]) -> str:
    """The runs' common task (runs from before SarSearch-v1 trained on v0)."""
    tasks = {run.config.get("task", "SarSearch-v0") for run in runs}
    if len(tasks) > 1:
        raise CompareError(f"the runs were trained on different tasks ({', '.join(sorted(tasks))}): compare one task")
    return tasks.pop()
