"""The comparison report: the markdown text and the figures (training curves, box plots) of ``hrlsac compare``.

The numbers come from :mod:`policies.reports.compare`; this module only renders them.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from policies.evaluation.stats import intervals_overlap
from policies.reports.figures import colour, new_figure, save_figure
from policies.reports.runs import BASELINE_LABELS, CURVE_COLUMNS, Run, label_of, train_command


def _pct(x: float | None) -> str:
    return "—" if x is None else f"{100 * x:.1f} %"


def _ci(interval) -> str:
    return "—" if interval is None else f"[{100 * interval[0]:.1f}, {100 * interval[1]:.1f}]"


def _num(x: float | None, fmt: str = ",.0f") -> str:
    return "—" if x is None else format(x, fmt)


def _seed_success(row: dict) -> str:
    if "seeds" not in row:
        return _pct(row["success"])
    if row["success_t95"] is None:
        return f"{_pct(row['success_mean'])} (1 seed: no interval)"
    return f"{100 * row['success_mean']:.1f} ± {100 * row['success_std']:.1f} % {_ci(row['success_t95'])}"


def _main_row(row: dict) -> str:
    seeds = str(row["seeds"]) if "seeds" in row else "scripted"
    cells = [row["label"], seeds, _seed_success(row), f"{_pct(row['success'])} {_ci(row['wilson95'])}",
             f"{row['reward_mean']:,.1f} ± {row['reward_std']:,.1f}",
             f"{row['coverage_mean']:.3f} ± {row['coverage_std']:.3f}",
             f"{row['length_mean']:,.0f} ± {row['length_std']:,.0f}",
             _pct(row["subgoal_reachability"]), _num(row["median_time_to_detection"])]
    return "| " + " | ".join(cells) + " |"


def _difference(a: float, b: float) -> str:
    """Relative difference of a from b, signed ("−21 %")."""
    return f"{100 * (a - b) / abs(b):+.0f} %".replace("-", "−") if b else "n/a"


def findings(summary: dict, groups: dict[tuple[str, str], list[Run]]) -> list[str]:
    """Plain statements read off the numbers (no claim that the numbers do not support)."""
    rows, baselines = summary["groups"], summary["baselines"]
    by_label = {row["label"]: row for row in rows}
    lines = []
    ranked = sorted(rows + baselines, key=lambda r: r["success"], reverse=True)
    lines.append(f"Highest pooled {summary['split']} success: {ranked[0]['label']}, {_pct(ranked[0]['success'])} "
                 f"{_ci(ranked[0]['wilson95'])}; lowest: {ranked[-1]['label']}, {_pct(ranked[-1]['success'])} "
                 f"{_ci(ranked[-1]['wilson95'])}.")
    for v in summary["verdicts"]:
        hrl, sac = by_label[v["hrl"]], by_label[v["sac"]]
        gap = 100 * (hrl["success_mean"] - sac["success_mean"])
        if v["seed_intervals_overlap"] is None:
            lines.append(f"{hrl['label']} vs {sac['label']}: an interval across seeds needs at least 2 seeds per "
                         f"method ({hrl['seeds']} and {sac['seeds']} here), so there is no verdict across seeds.")
        elif v["hrl_above_with_non_overlapping_intervals"]:
            lines.append(f"**{hrl['label']} is above {sac['label']} with non-overlapping 95 % intervals across "
                         f"seeds**: mean success {_pct(hrl['success_mean'])} {_ci(hrl['success_t95'])} vs "
                         f"{_pct(sac['success_mean'])} {_ci(sac['success_t95'])} ({gap:+.1f} points).")
        elif not v["seed_intervals_overlap"]:
            lines.append(f"**{hrl['label']} is below {sac['label']} with non-overlapping 95 % intervals across "
                         f"seeds**: mean success {_pct(hrl['success_mean'])} {_ci(hrl['success_t95'])} vs "
                         f"{_pct(sac['success_mean'])} {_ci(sac['success_t95'])} ({gap:+.1f} points).")
        else:
            lines.append(f"{hrl['label']} vs {sac['label']}: the 95 % intervals across seeds overlap "
                         f"({_ci(hrl['success_t95'])} vs {_ci(sac['success_t95'])}), so the {gap:+.1f}-point "
                         f"difference in mean success is not established with {hrl['seeds']} and {sac['seeds']} seeds.")
        lines.append(f"Pooled over all episodes, the Wilson intervals of {hrl['label']} {_ci(hrl['wilson95'])} and "
                     f"{sac['label']} {_ci(sac['wilson95'])} "
                     f"{'overlap' if v['pooled_intervals_overlap'] else 'do not overlap'} (pooled intervals ignore "
                     f"the seed-to-seed spread).")
        lines.append(f"{hrl['label']} vs {sac['label']}: mean episode length {hrl['length_mean']:,.0f} vs "
                     f"{sac['length_mean']:,.0f} steps ({_difference(hrl['length_mean'], sac['length_mean'])}), "
                     f"coverage {hrl['coverage_mean']:.3f} vs {sac['coverage_mean']:.3f}, reward "
                     f"{hrl['reward_mean']:,.1f} vs {sac['reward_mean']:,.1f}.")
    if baselines:
        best = max(baselines, key=lambda b: b["success"])
        for row in rows:
            relation = "above" if row["success"] > best["success"] else \
                "below" if row["success"] < best["success"] else "equal to"
            overlap = intervals_overlap(row["wilson95"], best["wilson95"])
            lines.append(f"{row['label']} pooled success {_pct(row['success'])} {_ci(row['wilson95'])} is {relation} "
                         f"the best scripted baseline, {best['label']} {_pct(best['success'])} "
                         f"{_ci(best['wilson95'])}; the Wilson intervals {'overlap' if overlap else 'do not overlap'}.")
    for row in rows:
        if row["subgoal_reachability"] is not None:
            lines.append(f"{row['label']} reached {_pct(row['subgoal_reachability'])} of its sub-goals "
                         f"(mean across seeds).")
    for key, members in groups.items():
        steps = sorted({m.config.get("total_steps") for m in members}, key=str)
        seeds = [m.config["seed"] for m in members]
        if len(set(seeds)) < len(seeds):
            lines.append(f"{label_of(key)} has runs with the same seed ({', '.join(map(str, sorted(seeds)))}); "
                         f"they are counted as separate seeds.")
        if len(steps) > 1:
            lines.append(f"The seeds of {label_of(key)} were trained for different numbers of steps "
                         f"({', '.join(map(str, steps))}); its spread mixes training lengths.")
    unsafe = [r for r in rows + baselines if (r["collision_rate"] or 0) > 0 or (r["out_of_bounds_rate"] or 0) > 0]
    lines.append("No collisions or geofence exits in any episode." if not unsafe else "Collisions / geofence exits: "
                 + ", ".join(f"{r['label']} {_pct(r['collision_rate'])} / {_pct(r['out_of_bounds_rate'])}"
                             for r in unsafe) + ".")
    return lines


def render_report(summary: dict, groups: dict[tuple[str, str], list[Run]], flight) -> str:
    split, episodes = summary["split"], summary["episodes"]
    rows, baselines = summary["groups"], summary["baselines"]
    out = [f"# Comparison on the {split} split", "",
           f"Generated {summary['generated_at']} by `{summary['command']}`.", "",
           f"Every method flew the first {episodes} scenarios of the {split} split once each (scenario i, "
           f"deterministic policy) with the same flight settings: altitude {flight.altitude_m:g} m, max speed "
           f"{flight.max_speed_mps:g} m/s, one step = {flight.step_period_s:g} s, K = {flight.subgoal_interval}, "
           f"step limit {flight.max_steps}, reach radius {flight.reach_radius_m:g} m."
           + (" The learned policies' evaluations were flown with the mission runner's rules (`hrlsac evaluate "
              "--flight-rules`: a ReturnToBase decision and the pilot's bingo failsafe end the search, as in a real "
              "flight); the scripted searchers fly their own rules either way."
              if str(summary.get("scenarios", "")).endswith("flight") else ""), "",
           "## Results", "",
           "| Method | seeds | success (mean ± std across seeds, 95 % CI) | pooled success [Wilson 95 %] | reward | "
           "coverage | length (steps) | sub-goal reachability | median time to find (steps) |",
           "|---|---|---|---|---|---|---|---|---|"]
    out += [_main_row(row) for row in rows]
    out += [_main_row({**row, "label": f"{row['label']} (scripted)"}) for row in baselines]
    out += ["", "| Method | detection rate | median time to find (steps) | median steps to success | collision rate | "
            "out-of-bounds rate |", "|---|---|---|---|---|---|"]
    out += [f"| {r['label']} | {_pct(r['detection_rate'])} | {_num(r['median_time_to_detection'])} | "
            f"{_num(r['median_steps_to_success'])} | {_pct(r['collision_rate'])} | {_pct(r['out_of_bounds_rate'])} |"
            for r in rows + baselines]
    if summary.get("task") == "SarSearch-v1":
        from policies.reports.groups import render_task_table

        out += [""] + render_task_table(summary)
    out += ["", "## What the numbers say", ""] + [f"- {line}" for line in findings(summary, groups)]
    out += ["", "## Figures", "",
            "![Training curves](training_curves.png)", "",
            "`training_curves.png`: success rate, return, coverage and episode length logged during training "
            "(each point of `progress.csv` is the mean over the last 100 training episodes, not the paper's "
            "10-episode moving average), mean across seeds with a min–max band; the scripted baselines' "
            f"{split}-split means are drawn as grey reference lines.", "",
            "![Test distributions](boxplots.png)", "",
            f"`boxplots.png`: per-episode {split} reward and episode length (all seeds pooled) and per-seed "
            "success rate, per method and scripted baseline.", "",
            "## Per-seed results", ""]
    for key, members in groups.items():
        out += [f"### {label_of(key)}", "",
                "| seed | trained steps | episodes | success [Wilson 95 %] | reward | coverage | length | "
                "sub-goal reachability | median time to find | run |", "|---|---|---|---|---|---|---|---|---|---|"]
        for run in members:
            m = run.metrics
            trained = m.get("trained_steps", run.config.get("total_steps"))
            out.append(f"| {run.config['seed']} | {_num(trained)} | {m['episodes']} | {_pct(m['success_rate'])} "
                       f"{_ci(m.get('success_ci95'))} | {m['reward_mean']:,.1f} ± {m['reward_std']:,.1f} | "
                       f"{m['coverage_mean']:.3f} ± {m['coverage_std']:.3f} | {m['length_mean']:,.0f} ± "
                       f"{m['length_std']:,.0f} | {_pct(m.get('subgoal_reachability'))} | "
                       f"{_num((m.get('time_to_first_detection') or {}).get('p50'))} | `{run.path}` |")
        out.append("")
    out += ["## How these numbers were produced", "", "```sh", "# training (reconstructed from each config.json)"]
    out += [train_command(run) for members in groups.values() for run in members]
    out += [f"# evaluation on the {split} split (writes RUN/eval_{split}.json)"]
    out += [run.eval_command for members in groups.values() for run in members]
    out += ["# this comparison (also evaluates the scripted baselines)", summary["command"], "```", "",
            "## Definitions", "",
            "- **success (across seeds)**: each seed's success rate on the split; mean, sample standard deviation "
            "and the 95 % Student-t interval of the mean (n − 1 degrees of freedom), clipped to [0, 1].",
            "- **pooled success**: all episodes of all seeds together, with a 95 % Wilson score interval.",
            "- **reward, coverage, length**: mean ± standard deviation over all episodes of all seeds (reward is "
            "the cumulative extrinsic reward; coverage the share of the search grid seen).",
            "- **sub-goal reachability**: share of the meta-controller's goal segments in which the drone came "
            "within the reach radius of the goal's point (mean across seeds; HRL-SAC only).",
            "- **median time to find**: median step of the first detection of the victim over the episodes in "
            "which it was detected (pooled); **median steps to success** likewise over the successful episodes.",
            "- **overlap**: two intervals overlap when neither lies entirely above the other."]
    return "\n".join(out) + "\n"


def _aligned(logs: list[dict], column: str, grid: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean, min and max across runs of one logged column, interpolated onto ``grid`` (NaN where no run has data)."""
    curves = np.full((len(logs), len(grid)), np.nan)
    for i, log in enumerate(logs):
        ok = np.isfinite(log[column])
        if ok.any():
            x, y = log["step"][ok], log[column][ok]
            curves[i] = np.where(grid >= x[0], np.interp(grid, x, y), np.nan)
    valid = np.isfinite(curves)
    count = valid.sum(axis=0)
    mean = np.where(count > 0, np.where(valid, curves, 0.0).sum(axis=0) / np.maximum(count, 1), np.nan)
    low = np.where(count > 0, np.where(valid, curves, np.inf).min(axis=0), np.nan)
    high = np.where(count > 0, np.where(valid, curves, -np.inf).max(axis=0), np.nan)
    return mean, low, high


def plot_training_curves(groups: dict[tuple[str, str], list[Run]], summary: dict, path: Path) -> None:
    """Logged training success, return, coverage and length per group: mean across seeds, min–max band."""
    from matplotlib.ticker import FuncFormatter

    fig = new_figure(13, 9)
    axes = fig.subplots(2, 2).ravel()
    plotted = False
    for index, (key, members) in enumerate(groups.items()):
        logs = [r.progress for r in members if r.progress is not None and len(r.progress["step"])]
        if not logs:
            continue
        end = min(log["step"][-1] for log in logs)  # the range every seed covers
        grid = np.unique(np.concatenate([log["step"][log["step"] <= end] for log in logs]))
        for ax, (column, _) in zip(axes, CURVE_COLUMNS):
            mean, low, high = _aligned(logs, column, grid)
            ax.plot(grid, mean, color=colour(index), linewidth=2,
                    label=f"{label_of(key)}, {len(logs)} seed{'s' if len(logs) > 1 else ''} (train)")
            if len(logs) > 1:
                ax.fill_between(grid, low, high, color=colour(index), alpha=0.2, linewidth=0)
        plotted = True
    styles = (":", "--", "-.")
    for i, row in enumerate(summary["baselines"]):
        values = {"success_rate": row["success"], "mean_return": row["reward_mean"],
                  "mean_coverage": row["coverage_mean"], "mean_length": row["length_mean"]}
        for ax, (column, _) in zip(axes, CURVE_COLUMNS):
            ax.axhline(values[column], color="0.35", linestyle=styles[i % 3], linewidth=1.2,
                       label=f"{row['label']} (scripted, {summary['split']} split)")
    for ax, (column, title) in zip(axes, CURVE_COLUMNS):
        ax.set_title(title)
        ax.set_xlabel("training step (environment steps)")
        ax.set_ylabel(title)
        ax.grid(alpha=0.3)
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x / 1000:g}k" if abs(x) >= 1000 else f"{x:g}"))
        if column == "success_rate":
            ax.set_ylim(-0.05, 1.05)
        if not plotted:
            ax.text(0.5, 0.5, "no progress.csv rows", transform=ax.transAxes, ha="center", va="center")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=min(3, max(1, len(labels))), frameon=False)
    fig.suptitle("Training curves (rolling mean over the last 100 training episodes; line = mean across seeds, "
                 "band = min–max)", fontsize=12)
    fig.tight_layout(rect=(0, 0.1, 1, 0.96))
    save_figure(fig, path)


def plot_boxplots(groups: dict[tuple[str, str], list[Run]], baselines: dict[str, dict], summary: dict,
                  path: Path) -> None:
    """Box plots of per-episode reward and length, and of per-seed success, per group and baseline."""
    labels = [label_of(key) for key in groups] + [BASELINE_LABELS.get(n, n) for n in baselines]
    colours = [colour(i) for i in range(len(groups))] + ["0.75"] * len(baselines)
    sources = [[r.metrics for r in members] for members in groups.values()] + [[m] for m in baselines.values()]

    def per_episode(name: str) -> list[np.ndarray]:
        return [np.concatenate([np.asarray((m.get("per_episode") or {}).get(name, []), dtype=np.float64)
                                for m in metrics]) for metrics in sources]

    fig = new_figure(max(12, 2.2 * len(labels) * 1.5), 6)
    axes = fig.subplots(1, 3)
    positions = np.arange(1, len(labels) + 1)
    panels = ((per_episode("reward"), f"Reward per {summary['split']} episode", "cumulative extrinsic reward"),
              (per_episode("length"), f"Length of each {summary['split']} episode", "episode length (steps)"))
    for ax, (data, title, ylabel) in zip(axes, panels):
        keep = [i for i, d in enumerate(data) if len(d)]
        if keep:
            boxes = ax.boxplot([data[i] for i in keep], positions=positions[keep], widths=0.6, patch_artist=True,
                               medianprops={"color": "black"})
            for patch, i in zip(boxes["boxes"], keep):
                patch.set_facecolor(colours[i])
        ax.set_title(title)
        ax.set_ylabel(ylabel)
    ax = axes[2]
    seed_rates = [[float(m["success_rate"]) for m in metrics] for metrics in sources]
    boxes = ax.boxplot(seed_rates[:len(groups)], positions=positions[:len(groups)], widths=0.6, patch_artist=True,
                       medianprops={"color": "black"}) if groups else {"boxes": []}
    for patch, i in zip(boxes["boxes"], range(len(groups))):
        patch.set_facecolor(colours[i])
        patch.set_alpha(0.5)
    jitter = np.random.default_rng(0)
    for i, rates in enumerate(seed_rates[:len(groups)]):
        ax.scatter(positions[i] + jitter.uniform(-0.12, 0.12, len(rates)), rates, color="black", s=18, zorder=3,
                   label="one seed" if i == 0 else None)
    if baselines:
        ax.scatter(positions[len(groups):], [r[0] for r in seed_rates[len(groups):]], marker="D", color="0.35",
                   s=36, zorder=3, label="scripted baseline (one run)")
    ax.set_ylim(-0.05, 1.05)
    ax.set_title(f"Success rate per seed ({summary['split']} split)")
    ax.set_ylabel("success rate")
    ax.legend(loc="best", fontsize=8)
    for ax in axes:
        ax.set_xticks(positions)
        ax.set_xticklabels(labels, rotation=25, ha="right")
        ax.set_xlim(0.4, len(labels) + 0.6)
        ax.grid(axis="y", alpha=0.3)
    fig.suptitle(f"{summary['split'].capitalize()} split, {summary['episodes']} episodes per seed "
                 f"(scenarios 0–{summary['episodes'] - 1})", fontsize=12)
    fig.tight_layout(rect=(0, 0, 1, 0.95))
    save_figure(fig, path)
