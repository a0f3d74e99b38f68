"""Policy export's manifest and refusals: the manifest round-trips and describes the checkpoint (and an "arrive"
policy's speed cap, and the evaluation of that checkpoint only), refusal of damaged or mismatched artifacts (another
observation layout, a SarSearch-v0 run, an unknown format version, truncated or corrupted files, files that are not
artifacts), and the export / policy info commands."""
from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import pytest
import torch
from export_helpers import FORMATS, K, single_line_error

import hrlsac_cli
from autonomy.observation import OBS_DIM
from autonomy.policy import load_policy
from autonomy.policy_cli import main as policy_main
from autonomy.policy_manifest import NOT_EVALUATED, PolicyManifest
from autonomy.torch_compat import torchscript_calls
from missions.goals import GOAL_NAMES
from policies.checkpoint import CheckpointPolicy
from policies.cli.export import main as export_main
from policies.config import TrainConfig
from policies.export.artifact import artifact_bytes, build_manifest, export_policy
from policies.export.module import policy_module
from policies.export.parity import ACTION_TOLERANCE


# ---------------------------------------------------------------------------------------------------- manifest
def test_manifest_round_trips_and_describes_the_checkpoint(runs, artifacts):
    for (algo, fmt), path in artifacts.items():
        manifest = load_policy(path).manifest
        policy = CheckpointPolicy.load(runs[algo])
        assert manifest == PolicyManifest.from_json(manifest.to_json())
        broken = {k: v for k, v in json.loads(manifest.to_json()).items() if k != "action"}
        with pytest.raises(ValueError, match="manifest is missing the field 'action'"):
            PolicyManifest.from_json(json.dumps(broken))
        message = 'manifest.subgoal_interval must be an integer or null, got "ten"'
        with pytest.raises(ValueError, match=re.escape(message)):
            PolicyManifest.from_json(json.dumps({**broken, "action": {}, "subgoal_interval": "ten"}))
        assert (manifest.format, manifest.algorithm, manifest.format_version) == (fmt, algo, 1)
        assert (manifest.precision, manifest.action_tolerance) == ("float32", ACTION_TOLERANCE)
        older = {k: v for k, v in json.loads(manifest.to_json()).items() if k not in ("precision", "action_tolerance")}
        assert PolicyManifest.from_json(json.dumps(older)) == manifest  # written before the fields: float32
        assert TrainConfig.from_dict(manifest.training_config) == policy.config
        assert manifest.source_checkpoint.trained_steps == policy.step == 400
        assert len(manifest.source_checkpoint.sha256) == 64
        assert manifest.observation.dim == OBS_DIM and manifest.observation.fields[-1]["name"] == "goal"
        assert manifest.action.names == ("movement_north", "movement_east", "search_intensity", "camera_zoom")
        assert manifest.evaluation == NOT_EVALUATED
        assert manifest.torch_version == torch.__version__
        if algo == "hrl-sac":
            assert manifest.subgoal_interval == K and tuple(g.name for g in manifest.goals) == GOAL_NAMES
            # SarSearch-v1's grounding (ground_goals_v1's documentation), not SarSearch-v0's coverage grid
            assert "belief cell" in manifest.goals[1].grounding and "candidate" in manifest.goals[2].grounding
            assert not any("coverage grid" in goal.grounding for goal in manifest.goals)
        else:
            assert manifest.subgoal_interval is None and manifest.goals == ()


def test_the_arrive_frame_manifest_states_the_speed_cap_the_environment_flies():
    """The manifest's unit of an "arrive" policy's movement must be the cap ``movement_velocity`` applies: the top
    speed, or the distance left over ARRIVAL_STEPS steps (one step would be twice as fast near the target)."""
    from missions.action_frames import movement_velocity
    from policies.config import TrainConfig
    from policies.export.artifact import build_manifest

    policy = CheckpointPolicy.untrained(TrainConfig.from_preset("default", algo="hrl-sac", action_frame="arrive"))
    unit = build_manifest(policy, "torchscript", "0" * 64).action.units[0]
    steps = float(re.search(r"distance to the target / \(([\d.]+) \* flight.step_period_s\)", unit).group(1))
    max_speed, period, distance = 10.0, 1.0, 6.0  # near the target: the distance cap binds
    velocity = movement_velocity(np.array([[1.0, 0.0]]), np.zeros((1, 2)), np.array([[distance, 0.0]]), "arrive",
                                 max_speed, period)
    assert velocity[0, 0] == pytest.approx(min(max_speed, distance / (steps * period))) and velocity[0, 1] == 0.0


def test_export_embeds_the_evaluation_of_that_checkpoint_only(runs, tmp_path):
    run = runs["sac"]
    metrics = {"split": "test", "trained_steps": 400, "episodes": 3, "success_rate": 0.5, "per_episode": {}}
    (run / "eval_test.json").write_text(json.dumps(metrics))
    (run / "eval_val.json").write_text(json.dumps({**metrics, "split": "val", "trained_steps": 200}))
    others = {  # under the flight rules, on other scenarios, and a constant goal's (not the policy's own)
        "eval_test_flight.json": {**metrics, "flight_rules": True, "success_rate": 0.6},
        "eval_test_generator-large.json": {**metrics, "scenarios": "generator-large", "success_rate": 0.2},
        "eval_test_goal-TrackObject.json": {**metrics, "constant_goal": 2, "success_rate": 0.9}}
    for name, content in others.items():
        (run / name).write_text(json.dumps(content))
    try:
        result = export_policy(run, tmp_path / "policy.pt")
    finally:
        for name in ("eval_test.json", "eval_val.json", *others):
            (run / name).unlink()
    plain = {k: v for k, v in metrics.items() if k != "per_episode"}
    assert result.manifest.evaluation == {
        "test": plain, "test, flight rules": {**plain, "flight_rules": True, "success_rate": 0.6},
        "test (generator-large)": {**plain, "scenarios": "generator-large", "success_rate": 0.2}}
    assert result.notes == ["left out eval_val.json: it evaluated step 200, the checkpoint is at step 400"]


# ---------------------------------------------------------------------------------------------------- refusals
def write_with_manifest(runs, path: Path, fmt: str, **changes) -> Path:
    policy = CheckpointPolicy.load(runs["hrl-sac"])
    manifest = dataclasses.replace(build_manifest(policy, fmt, "0" * 64), **changes)
    path.write_bytes(artifact_bytes(policy_module(policy), manifest))
    return path


@pytest.mark.parametrize("fmt", FORMATS)
def test_refuses_an_artifact_with_another_observation_layout(runs, tmp_path, fmt):
    current = build_manifest(CheckpointPolicy.load(runs["hrl-sac"]), fmt, "0" * 64).observation
    fields = tuple({**f, "size": 64} if f["name"] == "belief" else f for f in current.fields)
    path = write_with_manifest(runs, tmp_path / "policy.pt", fmt,
                               observation=dataclasses.replace(current, fields=fields))
    message = single_line_error(path, "observation layout of the artifact does not match")
    assert "field 'belief' at offset 16 size 64 vs 'belief' at offset 16 size 256" in message
    v0 = write_with_manifest(runs, tmp_path / "v0.pt", fmt, observation=dataclasses.replace(current, layout_version=3))
    assert "layout_version 3 vs 4" in single_line_error(v0, "observation layout of the artifact does not match")


def test_a_sarsearch_v0_run_is_not_exported_for_the_runtime_that_flies_v1():
    from policies.config import TrainConfig
    from policies.export.module import policy_module

    v0 = CheckpointPolicy.untrained(TrainConfig.from_preset("default", task="SarSearch-v0"))
    message = r"trained on SarSearch-v0 \(observation layout 3\); the runtime flies layout 4"
    with pytest.raises(ValueError, match=message):
        policy_module(v0)


def test_refuses_an_unknown_format_version(runs, tmp_path):
    path = write_with_manifest(runs, tmp_path / "policy.pt", "torchscript", format_version=2)
    single_line_error(path, r"unknown artifact format version 2 \(this runtime reads version 1\)")


@pytest.mark.parametrize("fmt", FORMATS)
def test_refuses_truncated_and_corrupted_files(artifacts, tmp_path, fmt):
    data = artifacts["hrl-sac", fmt].read_bytes()
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(data[:len(data) // 2])
    single_line_error(truncated, "truncated or damaged file")
    corrupt, middle = tmp_path / "corrupt.pt", len(data) // 2
    corrupt.write_bytes(data[:middle] + bytes(b ^ 0xFF for b in data[middle:middle + 8]) + data[middle + 8:])
    single_line_error(corrupt, "corrupt file")


def test_refuses_files_that_are_not_policy_artifacts(tmp_path):
    text = tmp_path / "notes.txt"
    text.write_text("not a policy\n")
    single_line_error(text, r"not a policy artifact \(not a zip archive")
    plain = tmp_path / "plain.pt"
    with torchscript_calls():
        torch.jit.save(torch.jit.script(torch.nn.Linear(2, 2)), str(plain))
    single_line_error(plain, r"not a policy artifact \(no manifest.json inside")
    single_line_error(tmp_path / "missing.pt", "no such file")


# ---------------------------------------------------------------------------------------------------- commands
def test_export_and_policy_info_commands(runs, tmp_path, capsys):
    assert {"export", "policy"} <= set(hrlsac_cli.COMMANDS)
    out = tmp_path / "policy.pt"
    assert export_main([str(runs["hrl-sac"]), "-o", str(out), "--format", "torch-export", "--check"]) == 0
    printed = capsys.readouterr().out
    assert f"wrote {out}" in printed and "hrl-sac policy, torch-export" in printed
    assert "parity with the checkpoint: 10,000 observations" in printed and printed.rstrip().endswith("ok")
    int8 = tmp_path / "policy-int8.pt"
    assert export_main([str(runs["hrl-sac"]), "-o", str(int8), "--precision", "int8", "--check"]) == 0
    assert "int8 (actions within 0.05 of the trained policy)" in capsys.readouterr().out
    assert load_policy(int8).manifest.precision == "int8"
    assert policy_main(["info", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "check: ok" in printed and "ReturnToBase: home" in printed
    assert "belief           offset  16 size 256" in printed
    assert policy_main(["info", "--json", str(out)]) == 0
    assert json.loads(capsys.readouterr().out)["algorithm"] == "hrl-sac"


@pytest.mark.parametrize("command, message", [
    (lambda tmp: export_main([str(tmp / "nothing"), "-o", str(tmp / "p.pt")]), "no checkpoint at"),
    (lambda tmp: export_main([str(tmp / "bad.pt"), "-o", str(tmp / "p.pt")]), "not a readable training checkpoint"),
    (lambda tmp: policy_main(["info", str(tmp / "bad.pt")]), "not a policy artifact"),
])
def test_commands_turn_bad_input_into_one_line(tmp_path, capsys, command, message):
    (tmp_path / "bad.pt").write_text("garbage")
    assert command(tmp_path) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "p.pt").exists()
