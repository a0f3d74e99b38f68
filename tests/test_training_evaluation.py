"""The training loop's evaluations and commands: checkpoint policies and their evaluation, quick evaluations during
training (logged, changing nothing, with or without the mission runner's flight rules), keep_best for flat SAC, the
progress bars, the train / evaluate commands, and the shipped policies' sweep-file recipes."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from cli_harness import run_cli
from training_helpers import log_rows, small_config

from autonomy.policy import load_policy
from policies.checkpoint import CheckpointPolicy
from policies.evaluation.parallel import evaluate_checkpoint, quick_evaluation
from policies.training.sweep_config import load_sweep
from policies.training.trainer import Trainer


def test_progress_bars_show_rate_and_time_left_on_stderr_and_change_nothing_else(tmp_path, capsys, monkeypatch):
    from policies.cli import evaluate as evaluate_command
    from hrlsac_cli import progress

    monkeypatch.setattr(progress, "LOG_EVERY_S", 0.0)  # not a terminal: a line at every update, from the first
    config = small_config("sac", total_steps=400)
    runs = {}
    for name, quiet in (("quiet", True), ("shown", False)):
        runs[name] = Trainer(config, tmp_path / name)
        runs[name].run(progress=not quiet)
        argv = [str(tmp_path / name), "--split", "val", "--episodes", "4", "--out", str(tmp_path / f"{name}.json")]
        assert evaluate_command.main(argv + (["--quiet"] if quiet else [])) == 0
        runs[name].stderr = capsys.readouterr().err.splitlines()
    assert runs["quiet"].stderr == []
    training = [line for line in runs["shown"].stderr if line.startswith("training:")]
    assert training[-1].startswith("training: 100%") and " 400/400 [" in training[-1]
    assert "step/s" in training[-1] and "<00:00" in training[-1] and "episodes " in training[-1]
    evaluating = [line for line in runs["shown"].stderr if line.startswith("evaluating:")]
    assert len(evaluating) > 2 and evaluating[-1].startswith("evaluating: 100%")  # step by step, in this process
    assert " 4/4 [" in evaluating[-1] and "episode/s" in evaluating[-1]
    assert log_rows(tmp_path / "quiet" / "progress.csv") == log_rows(tmp_path / "shown" / "progress.csv")
    for a, b in zip(runs["quiet"].low.actor.state_dict().values(), runs["shown"].low.actor.state_dict().values()):
        assert torch.equal(a, b)
    metrics = [json.loads((tmp_path / f"{name}.json").read_text()) for name in ("quiet", "shown")]
    assert [{k: v for k, v in m.items() if k != "checkpoint"} for m in metrics][0] == \
        {k: v for k, v in metrics[1].items() if k != "checkpoint"}


def test_checkpoint_policy_is_deterministic_and_evaluates(tmp_path):
    Trainer(small_config("hrl-sac", total_steps=400), tmp_path).run(progress=False)
    policy = CheckpointPolicy.load(tmp_path)
    assert policy.hierarchical and policy.step == 400
    obs = np.random.default_rng(0).uniform(0, 1, size=(5, 288)).astype(np.float32)
    np.testing.assert_array_equal(policy.act(obs), policy.act(obs))
    actions = policy.act(obs)
    assert np.all(actions >= [-1, -1, 0, 0]) and np.all(actions <= 1)
    assert set(policy.choose_goals(obs[:, :284]).tolist()) <= {0, 1, 2, 3}
    metrics = evaluate_checkpoint(tmp_path, "val", 6)
    assert metrics["episodes"] == 6 and 0.0 <= metrics["success_rate"] <= 1.0
    assert metrics["subgoal_reachability"] is not None
    assert metrics == evaluate_checkpoint(tmp_path, "val", 6)  # deterministic


def test_train_and_evaluate_commands(tmp_path):
    run = tmp_path / "run"
    base = [sys.executable, "-m", "hrlsac_cli"]
    result = subprocess.run([*base, "train", "--algo", "sac", "--steps", "300", "--out", str(run), "--quiet",
                             "--set", "warmup_steps=100", "--set", "num_envs=2", "--set", "batch_size=16"],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert json.loads((run / "config.json").read_text())["total_steps"] == 300
    # the rest in this process (tests/cli_harness.py): the same main(), without an interpreter start each
    again = run_cli("train", "--algo", "sac", "--steps", "300", "--out", str(run))
    assert again.code == 2 and "already holds a run" in again.err
    bad = run_cli("train", "--out", str(tmp_path / "x"), "--set", "warmup=5")
    assert bad.code == 2 and "expected FIELD=VALUE" in bad.err
    evaluated = run_cli("evaluate", str(run), "--split", "val", "--episodes", "4")
    assert evaluated.code == 0, evaluated.err
    metrics = json.loads((run / "eval_val.json").read_text())
    assert metrics["episodes"] == 4 and metrics["algo"] == "sac" and not metrics["flight_rules"]
    flown = run_cli("evaluate", str(run), "--split", "val", "--episodes", "4", "--flight-rules")
    assert flown.code == 0 and "eval_val_flight.json" in flown.out, flown.err
    assert json.loads((run / "eval_val_flight.json").read_text())["flight_rules"]
    missing = run_cli("evaluate", str(tmp_path / "nothing"))
    assert missing.code == 2 and "no checkpoint" in missing.err


def test_quick_evaluations_are_logged_and_do_not_change_training(tmp_path):
    plain = Trainer(small_config("hrl-sac", eval_every=0), tmp_path / "plain")
    plain.run(progress=False)
    evaluated = Trainer(small_config("hrl-sac", eval_every=200, eval_episodes=4), tmp_path / "evaluated",
                        evaluate=quick_evaluation)
    evaluated.run(progress=False)
    for a, b in zip(plain.low.actor.state_dict().values(), evaluated.low.actor.state_dict().values()):
        assert torch.equal(a, b)
    for a, b in zip(plain.meta.actor.state_dict().values(), evaluated.meta.actor.state_dict().values()):
        assert torch.equal(a, b)
    rows_plain, rows_evaluated = log_rows(tmp_path / "plain" / "progress.csv"), \
        log_rows(tmp_path / "evaluated" / "progress.csv")
    assert [row["eval_success_rate"] for row in rows_plain] == ["nan"] * len(rows_plain)
    evaluations = [row.pop("eval_success_rate") for row in rows_evaluated]
    ran_dry = [row.pop("eval_ran_dry_rate") for row in rows_evaluated]
    assert evaluations[0] == "nan" and all(0.0 <= float(value) <= 1.0 for value in evaluations[1:])
    assert ran_dry[0] == "nan" and all(0.0 <= float(value) <= 1.0 for value in ran_dry[1:])
    evaluated_fields = ("eval_success_rate", "eval_ran_dry_rate")
    assert [{k: v for k, v in row.items() if k not in evaluated_fields} for row in rows_plain] == rows_evaluated
    # the last evaluation is the final policy's success on the first 4 val scenarios, as hrlsac evaluate gives it
    final = evaluate_checkpoint(tmp_path / "evaluated", split="val", episodes=4)
    assert float(evaluations[-1]) == final["success_rate"]


def test_quick_evaluations_can_fly_with_the_mission_runners_rules(tmp_path):
    """eval_flight_rules: the quick evaluation is what hrlsac evaluate --flight-rules gives on the same scenarios."""
    import dataclasses

    trainer = Trainer(small_config("hrl-sac", eval_every=0), tmp_path)
    trainer.run(progress=False)
    policy = CheckpointPolicy.load(tmp_path)
    for rules in (False, True):
        policy.config = dataclasses.replace(policy.config, eval_flight_rules=rules, eval_episodes=6)
        quick = quick_evaluation(policy)
        full = evaluate_checkpoint(tmp_path, split="val", episodes=6, flight_rules=rules)
        assert quick == {"success_rate": full["success_rate"], "ran_dry_rate": full["ran_dry_rate"]}
        assert full["flight_rules"] == rules


def test_keep_best_ends_a_flat_run_with_the_policy_and_normaliser_of_the_best_evaluation(tmp_path):
    """keep_best (flat SAC): scripted scores make step 300 the best and step 700 only tie with it, so the run and
    its checkpoint end with step 300's actor and the normaliser its inputs had then; the critics, which do not act,
    are the last ones, as in a run without keep_best."""
    scripted = {300: 0.75, 700: 0.75}
    seen = {}

    def scripted_evaluation(policy):
        seen[policy.step] = ({k: v.clone() for k, v in policy.low.actor.state_dict().items()},
                             policy.normalizer.state_dict())
        return scripted.get(policy.step, 0.25)

    plain = Trainer(small_config("sac"), tmp_path / "plain")
    plain.run(progress=False)
    trainer = Trainer(small_config("sac", keep_best=True, eval_every=100, eval_episodes=4), tmp_path / "best",
                      evaluate=scripted_evaluation)
    trainer.run(progress=False)
    assert sorted(seen) == list(range(100, 900, 100))
    assert trainer.best["step"] == 300 and trainer.best["success"] == 0.75
    actor_300, normaliser_300 = seen[300]
    assert not all(torch.equal(actor_300[k], seen[800][0][k]) for k in actor_300)  # it learned after step 300
    assert not np.array_equal(normaliser_300["mean"], seen[800][1]["mean"])
    policy = CheckpointPolicy.load(tmp_path / "best")
    for actor in (trainer.low.actor.state_dict(), policy.low.actor.state_dict()):
        assert all(torch.equal(actor[k], actor_300[k]) for k in actor)
    np.testing.assert_array_equal(policy.normalizer.state_dict()["mean"], normaliser_300["mean"])
    np.testing.assert_array_equal(policy.normalizer.state_dict()["var"], normaliser_300["var"])
    for a, b in zip(plain.low.critic.state_dict().values(), trainer.low.critic.state_dict().values()):
        assert torch.equal(a, b)  # choosing is all it changes


def test_keep_best_is_the_flat_sacs_and_needs_quick_evaluations():
    with pytest.raises(ValueError, match=r"keep_best is the flat SAC's .*\(got 'hrl-sac' and 100\).*meta_keep_best"):
        small_config("hrl-sac", keep_best=True, eval_every=100)
    with pytest.raises(ValueError, match=r"keep_best .* eval_every above 0 \(got 'sac' and 0\)"):
        small_config("sac", keep_best=True, eval_every=0)
    with pytest.raises(ValueError, match=r"TrainConfig.keep_best chooses by quick evaluations: give the Trainer"):
        Trainer(small_config("sac", keep_best=True, eval_every=100), "unused-run-dir")


@pytest.mark.parametrize("artifact, sweep_file, run", [
    ("hrl-sac.pt", "hrl-sac.sweep.yaml", "hrl-sac-default-seed0"),
    ("sac.pt", "sac.sweep.yaml", "sac-default-seed0")])
def test_the_shipped_policies_are_the_sweep_file_runs_the_docs_name(artifact, sweep_file, run):
    # docs/training.md: `hrlsac train --sweep docs/results/SWEEP --run RUN` is the shipped policy's recipe; the
    # artifact's manifest carries the config it was trained with, which must be that run's, field for field.
    root = Path(__file__).resolve().parents[1]
    manifest = load_policy(root / "policies" / "pretrained" / artifact).manifest
    spec = {spec.name: spec for spec in load_sweep(root / "docs" / "results" / sweep_file).runs}[run]
    assert manifest.training_config == json.loads(json.dumps(spec.config.to_dict()))
