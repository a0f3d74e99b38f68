"""``benchmarks/baselines.py`` flies the searchers it is told to, over the detection streams asked for, on the
scenarios of a generator file, and refuses what it cannot fly with one line: the registered test look of the
lookahead planner (docs/results.md) is run with these options."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import baselines as baselines_benchmark  # noqa: E402

from policies.evaluation.baselines import run_baseline  # noqa: E402


def run(monkeypatch, *argv: str) -> int:
    monkeypatch.setattr(sys, "argv", ["baselines.py", *argv])
    return baselines_benchmark.main()


def test_only_streams_and_generator_fly_what_was_asked(tmp_path, monkeypatch):
    large = tmp_path / "large.yaml"
    large.write_text("area_size_m: 2000\ndatum_sigma_min_m: 100\ndatum_sigma_max_m: 250\n")
    out = tmp_path / "out.json"
    assert run(monkeypatch, "--split", "val", "--episodes", "6", "--only", "greedy_bayes", "--streams", "2",
               "--generator", str(large), "--out", str(out)) == 0
    report = json.loads(out.read_text())
    assert [(r["baseline"], r["stream"]) for r in report["results"]] == [("greedy_bayes", 0), ("greedy_bayes", 1)]
    rates = [r["success_rate"] for r in report["results"]]
    summary = report["streams"]["greedy_bayes"]
    assert summary["per_stream"] == rates and summary["mean"] == pytest.approx(sum(rates) / 2)
    low, high = summary["t95"]
    assert low <= summary["mean"] <= high
    # the generator file reached the scenarios: the same stream on the task's 1 km areas differs from the 2 km run
    from policies.cli.evaluate import read_generator_config

    again = run_baseline("greedy_bayes", "val", 6, stream=1, generator=read_generator_config(str(large)))
    assert again["per_episode"] == report["results"][1]["per_episode"]
    assert run_baseline("greedy_bayes", "val", 6, stream=1)["per_episode"] != again["per_episode"]


def test_each_searcher_is_paired_with_the_first(tmp_path, monkeypatch):
    """With several searchers each after the first gets its paired difference from the first, on the same
    scenarios, with a scenario-bootstrap interval around it."""
    out = tmp_path / "paired.json"
    argv = ["--split", "val", "--episodes", "8", "--only", "greedy_bayes,random", "--out", str(out)]
    assert run(monkeypatch, *argv) == 0
    report = json.loads(out.read_text())
    rates = {r["baseline"]: r["success_rate"] for r in report["results"]}
    paired = report["streams"]["random"]["minus_greedy_bayes"]
    assert rates["greedy_bayes"] > rates["random"]
    assert paired["mean"] == pytest.approx(rates["random"] - rates["greedy_bayes"])
    low, high = paired["scenario_bootstrap95"]
    assert low <= paired["mean"] <= high
    assert "greedy_bayes" not in report["streams"]  # one stream: no mean over streams, and no pair with itself


def test_an_unknown_searcher_or_no_stream_is_one_line(monkeypatch, capsys, tmp_path):
    for argv, message in ((["--only", "greedy_bayes,greedy"], "--only: no scripted searcher 'greedy' on SarSearch-v1; "
                           "choose from random, expanding_square, parallel_track, greedy_bayes, lookahead_bayes"),
                          (["--streams", "0"], "--streams must be >= 1, got 0")):
        with pytest.raises(SystemExit) as exit_info:
            run(monkeypatch, *argv, "--out", str(tmp_path / "never.json"))
        assert exit_info.value.code == 2
        assert message in capsys.readouterr().err
    assert not (tmp_path / "never.json").exists()
