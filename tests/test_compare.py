"""``hrlsac compare``: statistics across seeds, the report, the figures and the one-line errors.

The run folders are fakes with known numbers (config.json from the real presets, progress.csv rows, and
eval_test.json made by the evaluation's own ``summarise``); the scripted baselines really fly, on a few episodes.
"""
from __future__ import annotations

import csv
import io
import json
import math
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from policies.cli import compare as compare_cli
from policies.config import TrainConfig
from policies.evaluation.episodes import summarise
from policies.reports.compare import compare, t_interval, t_quantile_975
from policies.training.progress_log import LOG_FIELDS

EPISODES = 10
MAX_STEPS = 500  # every fake run (and so the baselines) flies with this step limit, not the preset's 1000


def wilson(successes: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return centre - half, centre + half


def episode_record(successes: int, seed: int, hierarchical: bool) -> dict[str, np.ndarray]:
    """Per-episode outcomes with ``successes`` of EPISODES successful; deterministic in ``seed``."""
    rng = np.random.default_rng(seed)
    success = np.arange(EPISODES) < successes
    length = np.where(success, rng.integers(50, 400, EPISODES), MAX_STEPS)
    first = np.where(success, length - rng.integers(5, 40, EPISODES), np.where(np.arange(EPISODES) % 3 == 0, 200, -1))
    segments = np.full(EPISODES, 6 if hierarchical else 0)
    return {"success": success, "collision": np.zeros(EPISODES, bool), "out_of_bounds": np.zeros(EPISODES, bool),
            "length": length, "first_detection": first,
            "episode_return": np.where(success, 100.0, 0.0) - 0.1 * length + rng.normal(0, 3, EPISODES),
            "coverage": rng.uniform(0.05, 0.4, EPISODES), "subgoal_segments": segments,
            "subgoals_reached": (segments * (0.5 + 0.1 * seed)).astype(np.int64)}


def make_run(root: Path, name: str, algo: str, seed: int, successes: int, **overrides) -> tuple[Path, dict]:
    """A run folder as hrlsac train + hrlsac evaluate leave it; returns (folder, per-episode record)."""
    run = root / name
    run.mkdir()
    overrides.setdefault("task", "SarSearch-v0")  # the report's own statistics; SarSearch-v1's rows: test_v1_rows
    config = TrainConfig.from_preset("default", algo=algo, seed=seed, total_steps=20_000, **overrides).to_dict()
    config["flight"]["max_steps"] = MAX_STEPS
    (run / "config.json").write_text(json.dumps(config, indent=2))
    with open(run / "progress.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=LOG_FIELDS)
        writer.writeheader()
        for i, step in enumerate(range(1_000, 20_001, 1_000)):
            learned = min(1.0, i / 15) * successes / EPISODES
            writer.writerow({**{k: math.nan for k in LOG_FIELDS}, "step": step, "episodes": 5 * i,
                             "success_rate": math.nan if i == 0 else learned, "mean_return": 100 * learned - 40,
                             "mean_length": MAX_STEPS - 300 * learned, "mean_coverage": 0.1 + 0.2 * learned,
                             "steps_per_s": 300.0})
    record = episode_record(successes, seed, algo == "hrl-sac")
    metrics = {"algo": algo, "preset": "default", "seed": seed, "checkpoint": str(run / "checkpoint.pt"),
               "trained_steps": 20_000, "split": "test", "max_steps": MAX_STEPS, **summarise(record)}
    (run / "eval_test.json").write_text(json.dumps(metrics, indent=2))
    return run, record


@pytest.fixture
def runs(tmp_path):
    """Three HRL-SAC seeds (6, 7, 8 of 10 successes) and three flat SAC seeds (1, 2, 3 of 10)."""
    made = {}
    for seed, (hrl, sac) in enumerate([(6, 1), (7, 2), (8, 3)]):
        made[("hrl-sac", seed)] = make_run(tmp_path, f"hrl-{seed}", "hrl-sac", seed, hrl,
                                           **({"num_envs": 4, "warmup_steps": 500} if seed == 0 else {}))
        made[("sac", seed)] = make_run(tmp_path, f"sac-{seed}", "sac", seed, sac)
    return made


def test_t_quantiles_match_the_t_distribution():
    # the printed tables' values (rounded to 6 decimals), and the normal quantile for many degrees of freedom
    for dof, tabled in ((1, 12.706205), (2, 4.302653), (4, 2.776445), (9, 2.262157), (29, 2.045230), (120, 1.979930)):
        assert t_quantile_975(dof) == pytest.approx(tabled, abs=5e-7)
    assert t_quantile_975(30) > t_quantile_975(35) > t_quantile_975(40)
    assert t_quantile_975(10**6) == pytest.approx(1.959964, abs=1e-5)
    with pytest.raises(ValueError, match="dof must be >= 1, got 0"):
        t_quantile_975(0)
    mean, std, (low, high) = t_interval([0.6, 0.7, 0.8])
    assert (mean, std) == pytest.approx((0.7, 0.1))
    assert (low, high) == pytest.approx((0.7 - 4.302653 * 0.1 / math.sqrt(3), 0.7 + 4.302653 * 0.1 / math.sqrt(3)))
    assert t_interval([0.5])[1:] == (None, None)


def test_report_statistics_verdict_commands_and_figures(runs, tmp_path):
    out = tmp_path / "report"
    paths = [runs[key][0] for key in sorted(runs)]
    summary = compare(paths, out, split="test", progress=None)
    report = (out / "report.md").read_text()

    # across seeds: mean 70 %, sample std 10 points, t(2) interval; SAC's lower bound is clipped at 0
    half = 4.302653 * 0.1 / math.sqrt(3)
    assert f"| HRL-SAC (default) | 3 | 70.0 ± 10.0 % [{100 * (0.7 - half):.1f}, {100 * (0.7 + half):.1f}] |" in report
    assert f"| flat SAC (default) | 3 | 20.0 ± 10.0 % [0.0, {100 * (0.2 + half):.1f}] |" in report
    assert "[45.2, 94.8]" in report and "[0.0, 44.8]" in report
    # pooled: 21 / 30 and 6 / 30 with Wilson intervals
    for label, successes in (("HRL-SAC (default)", 21), ("flat SAC (default)", 6)):
        low, high = wilson(successes, 30)
        assert f"{100 * successes / 30:.1f} % [{100 * low:.1f}, {100 * high:.1f}]" in report
        row = next(line for line in report.splitlines() if line.startswith(f"| {label} |"))
        records = [runs[(("hrl-sac" if label.startswith("HRL") else "sac"), s)][1] for s in range(3)]
        reward = np.concatenate([r["episode_return"] for r in records])
        length = np.concatenate([r["length"] for r in records])
        coverage = np.concatenate([r["coverage"] for r in records])
        first = np.concatenate([r["first_detection"] for r in records])
        assert f"{reward.mean():,.1f} ± {reward.std():,.1f}" in row
        assert f"{coverage.mean():.3f} ± {coverage.std():.3f}" in row
        assert f"{length.mean():,.0f} ± {length.std():,.0f}" in row
        assert row.rstrip(" |").endswith(f"{np.median(first[first >= 0]):,.0f}")
    hrl_row = next(line for line in report.splitlines() if line.startswith("| HRL-SAC (default) |"))
    assert f"{100 * np.mean([3 / 6, 3 / 6, 4 / 6]):.1f} %" in hrl_row  # reachability: 3, 3 (int 3.6), 4 of 6
    sac_row = next(line for line in report.splitlines() if line.startswith("| flat SAC (default) |"))
    assert "| — |" in sac_row

    # the verdict: 45.2 > 44.8, so HRL-SAC is above flat SAC with non-overlapping intervals
    assert summary["verdicts"][0]["hrl_above_with_non_overlapping_intervals"] is True
    assert "**HRL-SAC (default) is above flat SAC (default) with non-overlapping 95 % intervals across seeds**" \
        in report

    # the baselines are rows, flown with the runs' flight settings
    for label in ("Random (scripted)", "Expanding square (scripted)", "Parallel track (scripted)"):
        assert f"| {label} | scripted |" in report
    assert "step limit 500" in report
    assert all(b["episodes"] == EPISODES and b["length_mean"] <= MAX_STEPS for b in summary["baselines"])

    # the commands: reconstructed training commands, evaluation commands and the compare command
    hrl0, sac2 = runs[("hrl-sac", 0)][0], runs[("sac", 2)][0]
    assert (f"hrlsac train --algo hrl-sac --preset default --steps 20000 --seed 0 --set task=SarSearch-v0 "
            f"--num-envs 4 --set warmup_steps=500 --out {hrl0}  # config.json also sets flight.max_steps=500") in report
    assert f"hrlsac train --algo sac --preset default --steps 20000 --seed 2 --set task=SarSearch-v0 --out {sac2}" \
        in report
    assert f"hrlsac evaluate {sac2} --split test --episodes {EPISODES}" in report
    assert summary["command"] in report and summary["command"].startswith("hrlsac compare ")
    assert "## Per-seed results" in report and "### flat SAC (default)" in report

    for name in ("training_curves.png", "boxplots.png"):
        image = cv2.imread(str(out / name))
        assert image is not None, name
        assert image.shape[0] >= 500 and image.shape[1] >= 1000
        assert image.std() > 10  # not a blank canvas
    assert json.loads((out / "summary.json").read_text())["groups"][0]["seeds"] == 3
    assert not list(out.glob("*.tmp*"))


def test_overlapping_intervals_and_a_single_seed_are_reported_as_such(tmp_path):
    paths = [make_run(tmp_path, f"hrl-{s}", "hrl-sac", s, k)[0] for s, k in enumerate((5, 7, 6))]
    paths += [make_run(tmp_path, f"sac-{s}", "sac", s, k)[0] for s, k in enumerate((4, 6, 5))]
    summary = compare(paths, tmp_path / "a", progress=None)
    verdict = summary["verdicts"][0]
    assert verdict["seed_intervals_overlap"] is True and not verdict["hrl_above_with_non_overlapping_intervals"]
    assert "the 95 % intervals across seeds overlap" in (tmp_path / "a" / "report.md").read_text()

    summary = compare(paths[:1] + paths[3:4], tmp_path / "b", progress=None)
    assert summary["verdicts"][0]["seed_intervals_overlap"] is None
    report = (tmp_path / "b" / "report.md").read_text()
    assert "| HRL-SAC (default) | 1 | 50.0 % (1 seed: no interval) |" in report
    assert "there is no verdict across seeds" in report


def test_cli_writes_the_report_and_prints_progress(runs, tmp_path):
    paths = [str(runs[("hrl-sac", s)][0]) for s in range(2)] + [str(runs[("sac", 0)][0])]
    result = subprocess.run([sys.executable, "-m", "hrlsac_cli", "compare", *paths, "--out", str(tmp_path / "cli"),
                             "--episodes", str(EPISODES)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    progress = result.stderr.strip().splitlines()  # not a terminal, and shorter than a progress line's interval
    assert len(progress) == 3 + 3 and progress[0].startswith("[run 1/3]") and progress[-1].startswith("[baseline 3/3]")
    assert "written" in result.stdout
    report = (tmp_path / "cli" / "report.md").read_text()
    assert f"hrlsac compare {paths[0]} {paths[1]} {paths[2]} --out {tmp_path / 'cli'} --episodes {EPISODES}" in report
    assert cv2.imread(str(tmp_path / "cli" / "boxplots.png")) is not None


def test_the_progress_bar_counts_the_episodes_to_fly(runs, tmp_path, monkeypatch):
    from hrlsac_cli import progress

    monkeypatch.setattr(progress, "LOG_EVERY_S", 0.0)  # not a terminal: a line at every update, from the first
    stream = io.StringIO()
    compare([str(runs[("sac", 0)][0])], tmp_path / "out", episodes=EPISODES, progress=stream)
    lines = stream.getvalue().splitlines()
    done = [line for line in lines if line.startswith("[")]  # and the bar's lines
    assert done[0].startswith("[run 1/1]") and sum(line.startswith("[baseline ") for line in done) == 3
    # the run has its evaluation: the episodes to fly are the three SarSearch-v0 baselines'
    assert "100%|" in lines[-1] and f" {3 * EPISODES}/{3 * EPISODES} [" in lines[-1] and "episode/s" in lines[-1]


def _one_line_error(capsys, argv) -> str:
    assert compare_cli.main(argv) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    return err


def test_errors_are_one_line_with_exit_code_2(runs, tmp_path, capsys):
    out = str(tmp_path / "out")
    assert "no runs given" in _one_line_error(capsys, ["--out", out])
    assert "no runs given" in _one_line_error(capsys, [])
    hrl0 = runs[("hrl-sac", 0)][0]
    assert "--out DIR is required" in _one_line_error(capsys, [str(hrl0)])

    empty = tmp_path / "empty"
    empty.mkdir()
    assert f"{empty}: no config.json" in _one_line_error(capsys, [str(hrl0), str(empty), "--out", out])
    assert "no such run folder" in _one_line_error(capsys, [str(tmp_path / "nope"), "--out", out])
    err = _one_line_error(capsys, [str(hrl0), "--scripted", "greedy_bayes,greedy", "--out", out])
    assert "--scripted: no scripted searcher 'greedy'; choose from random, expanding_square" in err

    (runs[("sac", 1)][0] / "eval_test.json").unlink()
    err = _one_line_error(capsys, [str(hrl0), str(runs[("sac", 1)][0]), "--out", out])
    assert "no eval_test.json" in err and "--evaluate" in err
    err = _one_line_error(capsys, [str(hrl0), "--episodes", "20", "--out", out])
    assert "has 10 episodes, not 20" in err

    (runs[("sac", 0)][0] / "progress.csv").write_text("step,success_rate\n1000,zero\n")
    assert "progress.csv: unreadable CSV" in _one_line_error(capsys, [str(runs[("sac", 0)][0]), "--out", out])
    (runs[("sac", 2)][0] / "progress.csv").write_bytes(b"\xff\xfe\x00garbage")
    assert "progress.csv: unreadable CSV" in _one_line_error(capsys, [str(runs[("sac", 2)][0]), "--out", out])

    other = runs[("hrl-sac", 1)][0]
    config = json.loads((other / "config.json").read_text())
    config["flight"]["altitude_m"] = 80.0
    (other / "config.json").write_text(json.dumps(config))
    err = _one_line_error(capsys, [str(hrl0), str(other), "--out", out])
    assert "runs disagree on flight settings" in err and "altitude_m 50.0 vs 80.0" in err

    # --evaluate needs a checkpoint; these fakes have none
    err = _one_line_error(capsys, [str(runs[("sac", 1)][0]), "--evaluate", "--out", out])
    assert "cannot evaluate" in err and "no checkpoint" in err
    assert not Path(out).exists()


def test_v1_rows_scripted_streams_constant_goals_iqm_and_verdicts(tmp_path):
    """SarSearch-v1 runs get the scripted searchers over detection streams, the constant-goal rows read from the
    runs' eval files, an IQM over runs x condition strata (recomputed here with scipy's trimmed mean) and the
    verdicts of HRL-SAC against every row."""
    scipy_stats = pytest.importorskip("scipy.stats")
    from missions.generator import TASK_V1, generate_scenario, scenario_seeds

    paths = []
    for seed, successes in enumerate((6, 7, 8)):
        run, _ = make_run(tmp_path, f"hrl-{seed}", "hrl-sac", seed, successes, task="SarSearch-v1")
        goal_metrics = json.loads((run / "eval_test.json").read_text())
        goal_metrics.update(summarise(episode_record(2, seed + 10, True)))
        (run / "eval_test_goal-TrackObject.json").write_text(json.dumps(goal_metrics))
        paths.append(run)
    paths += [make_run(tmp_path, f"sac-{seed}", "sac", seed, 1, task="SarSearch-v1")[0] for seed in range(3)]
    summary = compare(paths, tmp_path / "report", split="test", progress=None, streams=1)
    report = (tmp_path / "report" / "report.md").read_text()
    assert "## SarSearch-v1: every method on the same scenarios" in report
    scripted = {row["baseline"]: row for row in summary["baselines"]}
    assert set(scripted) == {"random", "expanding_square", "parallel_track", "greedy_bayes", "lookahead_bayes"}
    assert all(row["seeds"] == 1 and row["episodes"] == EPISODES for row in scripted.values())
    # --scripted flies only the named searchers; every detection stream is one seed of the row
    only = compare(paths, tmp_path / "only", split="test", progress=None, streams=2, scripted=["random"])
    assert [row["baseline"] for row in only["baselines"]] == ["random"]
    assert only["baselines"][0]["seeds"] == 2 and only["baselines"][0]["episodes"] == 2 * EPISODES
    assert [row["label"] for row in summary["constant_goals"]] == ["HRL-SAC's low level, always TrackObject"]
    assert summary["constant_goals"][0]["success_mean"] == pytest.approx(0.2)
    # the IQM of HRL-SAC's row: 3 runs x the strata of these 10 scenarios, trimmed by a quarter each side
    scenarios = [generate_scenario(s, TASK_V1) for s in scenario_seeds("test", EPISODES)]
    strata = np.array([int(s.conditions.time_of_day) * 3 + int(s.conditions.sea) for s in scenarios])
    runs = [np.arange(EPISODES) < k for k in (6, 7, 8)]
    scores = np.array([[run[strata == k].mean() for k in sorted(set(strata))] for run in runs])
    hrl = next(row for row in summary["groups"] if row["algo"] == "hrl-sac")
    if scores.size % 4 == 0:  # scipy's trimmed mean drops whole scores: equal where a quarter is a whole number
        assert hrl["aggregate"]["iqm"] == pytest.approx(scipy_stats.trim_mean(scores.ravel(), 0.25))
    low, high = hrl["aggregate"]["iqm_ci95"]
    assert 0.0 <= low <= hrl["aggregate"]["iqm"] <= high <= 1.0
    verdicts = {v["against"]: v for v in summary["task_verdicts"]}
    # against a row of one stream there is no spread across seeds; against two, 70 % vs 0 % do not overlap
    assert verdicts["Random"]["above_non_overlapping_seeds"] is False
    assert {v["against"]: v for v in only["task_verdicts"]}["Random"]["above_non_overlapping_seeds"]
    assert set(verdicts) >= {"flat SAC (default)", "HRL-SAC's low level, always TrackObject", "Greedy Bayesian"}
    assert (tmp_path / "report" / "found_by.png").exists()
    # the mean extrinsic reward across runs (it prices a lost aircraft), with its t interval, and its verdict
    expected = np.mean([json.loads((p / "eval_test.json").read_text())["reward_mean"] for p in paths[:3]])
    assert hrl["reward_seed_mean"] == pytest.approx(expected) and hrl["reward_t95"][0] <= expected
    assert verdicts["Random"]["hrl_reward_mean"] == pytest.approx(expected)
    assert f"reward {expected:.1f} vs" in report
    # hrlsac compare --flight-rules reads the runs' eval_test_flight[_goal-GOAL].json
    for path in paths:
        for name in ("eval_test.json", "eval_test_goal-TrackObject.json"):
            if (path / name).exists():
                flown = name.replace("eval_test", "eval_test_flight")
                (path / flown).write_text((path / name).read_text())
    flight = compare(paths, tmp_path / "flight", split="test", progress=None, streams=1, scenarios="flight",
                     scripted=["random"])
    assert "flown with the mission runner's rules" in (tmp_path / "flight" / "report.md").read_text()
    assert [row["label"] for row in flight["constant_goals"]] == ["HRL-SAC's low level, always TrackObject"]
