"""Policy export and the on-board runtime: parity with the eager policy on recorded observations (both formats),
the manifest, refusal of damaged or mismatched artifacts, the runtime without the training code, and the commands."""
from __future__ import annotations

import dataclasses
import json
import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

import hrlsac_cli
from autonomy.observation import META_OBS_DIM, OBS_DIM
from autonomy.policy import PolicyArtifactError, load_policy
from autonomy.policy_cli import main as policy_main
from autonomy.policy_manifest import NOT_EVALUATED, PolicyManifest, summary_lines
from autonomy.torch_compat import TORCHSCRIPT_DEPRECATION, torchscript_calls
from missions.goals import GOAL_NAMES, goal_due
from missions.mission import FlightSettings
from policies.checkpoint import CheckpointPolicy
from policies.cli.export import main as export_main
from policies.config import NetworkConfig, TrainConfig
from policies.export.artifact import ParityError, artifact_bytes, build_manifest, export_policy
from policies.export.module import PRECISIONS, policy_module
from policies.export.parity import (
    ACTION_TOLERANCE,
    INT8_ACTION_TOLERANCE,
    TOLERANCES,
    Parity,
    check_parity,
    record_observations,
)
from policies.training.trainer import Trainer

ALGOS = ("hrl-sac", "sac")
FORMATS = ("torchscript", "torch-export")
K = 10
# Small networks, but every kind of layer the presets use: LayerNorm, Dropout (must be off), the extra head layer.
NET = NetworkConfig(hidden=(32, 32), head=16, dropout=0.1)


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    """A few hundred training steps of each algorithm (parity needs a checkpoint, not a good policy); flat SAC's
    with an action margin, so that its artifact must clip as the eager policy does."""
    out = {}
    for algo in ALGOS:
        config = TrainConfig.from_preset(
            "default", algo=algo, seed=1, total_steps=400, num_envs=2, warmup_steps=100, batch_size=32,
            meta_batch_size=8, buffer_size=2_000, meta_buffer_size=500, checkpoint_every=10**6, log_every=10**6,
            eval_every=0, actor=NET, critic=NET, meta_actor=NET, meta_critic=NET,
            flight=FlightSettings(max_steps=120, subgoal_interval=K), action_margin=0.25 if algo == "sac" else 0.0)
        out[algo] = tmp_path_factory.mktemp(algo)
        Trainer(config, out[algo]).run(progress=False)
    return out


@pytest.fixture(scope="module")
def artifacts(runs, tmp_path_factory) -> dict[tuple[str, str], Path]:
    folder = tmp_path_factory.mktemp("artifacts")
    return {(algo, fmt): export_policy(runs[algo], folder / f"{algo}-{fmt}.pt", fmt).path
            for algo in ALGOS for fmt in FORMATS}


@pytest.fixture(scope="module")
def recorded(runs) -> dict[str, np.ndarray]:
    return {algo: record_observations(CheckpointPolicy.load(runs[algo])) for algo in ALGOS}


def single_line_error(path: Path, match: str) -> str:
    with pytest.raises(PolicyArtifactError, match=match) as info:
        load_policy(path)
    message = str(info.value)
    assert isinstance(info.value, ValueError) and "\n" not in message and message.startswith(str(path))
    return message


# ---------------------------------------------------------------------------------------------------- parity
@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("algo", ALGOS)
def test_artifact_acts_like_the_eager_policy_on_recorded_observations(runs, artifacts, recorded, algo, fmt):
    obs = recorded[algo]
    assert obs.shape == (10_000, OBS_DIM) and obs.dtype == np.float32
    assert len(np.unique(obs[:, :4], axis=0)) > 1_000  # flown, not one state repeated
    policy, artifact = CheckpointPolicy.load(runs[algo]), load_policy(artifacts[algo, fmt])
    parity = check_parity(policy, artifact, obs)
    assert parity.max_action_difference <= ACTION_TOLERANCE and parity.goal_mismatches == 0, parity.summary()
    goals = artifact.select_goal(obs[:, :META_OBS_DIM])
    if algo == "hrl-sac":
        assert obs[:, META_OBS_DIM:].sum(axis=1).min() == 1  # every recorded step had a goal
        assert np.array_equal(goals, policy.choose_goals(obs[:, :META_OBS_DIM]))
    else:
        assert (goals == -1).all()


def flushes_denormals() -> bool:
    """Whether this thread's float arithmetic runs in flush-to-zero / denormals-are-zero mode."""
    return torch.tensor([1e-39]).mul(1.0).item() == 0.0


def test_runtime_flushes_denormals_inside_its_calls_only(artifacts, recorded):
    """Denormal inputs (tiny belief probabilities) cost a microcode assist per multiply on x86: the programs run
    with flush-to-zero on (autonomy/policy.py), which must leave the actions and goals those of the zeroed inputs,
    and the caller's arithmetic (the simulation's, in a replay) as it was."""
    tiny = np.finfo(np.float32).tiny
    obs = recorded["hrl-sac"]
    denormal = (obs != 0) & (np.abs(obs) < tiny)
    assert denormal.any(axis=1).mean() > 0.05  # the environment really produces them
    rows = obs[denormal.any(axis=1)][:200]
    zeroed = np.where(np.abs(rows) < tiny, np.float32(0.0), rows).astype(np.float32)
    policy = load_policy(artifacts["hrl-sac", "torchscript"])
    seen = []
    for name in ("_act", "_select_goal"):
        program = getattr(policy, name)
        setattr(policy, name, lambda x, program=program: (seen.append(flushes_denormals()), program(x))[1])
    assert not flushes_denormals()
    actions, goals = policy.act(rows), policy.select_goal(rows[:, :META_OBS_DIM])
    assert seen == [True, True]  # on inside both programs ...
    assert not flushes_denormals()  # ... and off again after them
    assert np.array_equal(actions, policy.act(zeroed))
    assert np.array_equal(goals, policy.select_goal(zeroed[:, :META_OBS_DIM]))


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("algo", ALGOS)
def test_int8_artifact_keeps_goals_and_actions_within_its_stated_tolerance(runs, recorded, tmp_path, algo, fmt):
    """precision "int8" (the low-level actor's hidden layers): the parity check against INT8_ACTION_TOLERANCE passes
    (the export writes nothing otherwise), goals are exactly the trained ones, the manifest states both."""
    result = export_policy(runs[algo], tmp_path / "policy.pt", fmt, check=True, precision="int8")
    assert result.parity.ok and result.parity.tolerance == INT8_ACTION_TOLERANCE == 0.05
    artifact, policy = load_policy(result.path), CheckpointPolicy.load(runs[algo])
    assert (artifact.manifest.precision, artifact.manifest.action_tolerance) == ("int8", INT8_ACTION_TOLERANCE)
    assert f"{fmt} (artifact format 1, int8 (actions within 0.05 of the trained policy))" in summary_lines(
        artifact.manifest)[0]
    obs = recorded[algo]
    difference = np.abs(artifact.act(obs) - policy.act(obs))
    assert 0.0 < difference.max() <= INT8_ACTION_TOLERANCE  # really int8, and within the stated tolerance
    expected = policy.choose_goals(obs[:, :META_OBS_DIM]) if algo == "hrl-sac" else -1
    assert np.array_equal(artifact.select_goal(obs[:, :META_OBS_DIM]), np.broadcast_to(expected, len(obs)))
    assert tuple(TOLERANCES) == PRECISIONS  # every precision has its tolerance
    with pytest.raises(ValueError, match="unknown precision 'int4'"):
        export_policy(runs[algo], tmp_path / "other.pt", fmt, precision="int4")


def test_artifact_module_clips_to_the_action_ranges_under_an_action_margin(runs):
    policy = CheckpointPolicy.load(runs["sac"])  # trained with action_margin 0.25: movement [-1.5, 1.5], others
    assert policy.config.action_margin == 0.25   # [-0.25, 1.25], clipped to the environment's ranges
    mean_head = policy.low.actor.mean
    with torch.no_grad():  # the same pre-tanh mean for every observation
        mean_head.weight.zero_()
        mean_head.bias.copy_(torch.tensor([1.2, -2.0, 0.5, -0.3]))
    unit = np.tanh([1.2, -2.0, 0.5, -0.3])
    expected = np.array([1.0, -1.0, 0.5 + 0.75 * unit[2], 0.5 + 0.75 * unit[3]], dtype=np.float32)
    obs = np.random.default_rng(0).standard_normal((5, OBS_DIM)).astype(np.float32)
    np.testing.assert_allclose(policy.act(obs), np.tile(expected, (5, 1)), rtol=1e-6)
    module_actions = policy_module(policy).act(torch.from_numpy(obs)).numpy()
    np.testing.assert_allclose(module_actions, policy.act(obs), rtol=1e-6)


@pytest.mark.parametrize("fmt", FORMATS)
def test_plain_torch_loaders_run_the_artifact(runs, artifacts, recorded, fmt):
    obs = torch.from_numpy(recorded["hrl-sac"][:500])
    path, policy = artifacts["hrl-sac", fmt], CheckpointPolicy.load(runs["hrl-sac"])
    with torch.inference_mode():
        if fmt == "torchscript":
            with torchscript_calls():
                module = torch.jit.load(str(path))
            actions, goals = module.act(obs), module.select_goal(obs[:, :META_OBS_DIM])
            module.train()  # Dropout is gone from the artifact: train mode cannot make it random
            assert torch.equal(module.act(obs), actions)
            with pytest.raises(torch.jit.Error, match=r"shape \(N, 288\)"):
                module.act(obs[:, :275])
        else:
            extra = {"manifest.json": ""}  # torch.export.load fills a non-empty dict only
            with path.open("rb") as handle:  # a file object: a path is expected to end in .pt2
                actions = torch.export.load(handle, extra_files=extra).module()(obs)  # "model" is act
            assert json.loads(extra["manifest.json"])["format"] == "torch-export"
            goals = None
    np.testing.assert_allclose(actions.numpy(), policy.act(obs.numpy()), rtol=0, atol=ACTION_TOLERANCE)
    if goals is not None:
        assert np.array_equal(goals.numpy(), policy.choose_goals(obs[:, :META_OBS_DIM].numpy()))


def test_failed_parity_check_writes_nothing(runs, tmp_path, monkeypatch):
    monkeypatch.setattr("policies.export.artifact.check_parity", lambda *args: Parity(10, 1e-3, 0))
    with pytest.raises(ParityError, match="parity check failed"):
        export_policy(runs["sac"], tmp_path / "policy.pt", check=True)
    assert list(tmp_path.iterdir()) == []


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


# ---------------------------------------------------------------------------------------------------- runtime
def test_runtime_exposes_the_hierarchy(artifacts, recorded):
    hierarchical, flat = load_policy(artifacts["hrl-sac", "torchscript"]), load_policy(artifacts["sac", "torchscript"])
    assert hierarchical.subgoal_interval == K and flat.subgoal_interval is None
    assert [step for step in range(25) if hierarchical.goal_due(step)] == [0, 10, 20]
    assert [step for step in range(25) if goal_due(step, hierarchical.subgoal_interval)] == [0, 10, 20]
    assert not any(flat.goal_due(step) for step in range(25))
    obs = recorded["hrl-sac"][:3]
    action, goal = hierarchical.act(obs[0]), hierarchical.select_goal(obs[0, :META_OBS_DIM])
    assert action.shape == (4,) and action.dtype == np.float32
    np.testing.assert_allclose(action, hierarchical.act(obs)[0], rtol=0, atol=ACTION_TOLERANCE)  # other batch size
    assert 0 <= int(goal) < len(GOAL_NAMES)
    with pytest.raises(ValueError, match=r"shape \(N, 288\)"):
        hierarchical.act(obs[:, :META_OBS_DIM])


def test_runtime_loads_and_runs_artifacts_without_the_training_code(artifacts, recorded, runs, tmp_path):
    obs = recorded["hrl-sac"][:64]
    np.save(tmp_path / "obs.npy", obs)
    paths = [str(artifacts["hrl-sac", fmt]) for fmt in FORMATS]
    code = f"""
import importlib.abc, json, sys
class HidePolicies(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == "policies" or name.startswith("policies."):
            raise ImportError("the training code is not on this computer: " + name)
sys.meta_path.insert(0, HidePolicies())
import numpy as np
from autonomy.policy import load_policy
obs = np.load({str(tmp_path / "obs.npy")!r})
out = []
for path in {paths!r}:
    policy = load_policy(path)
    out.append([policy.act(obs).tolist(), policy.select_goal(obs[:, :284]).tolist()])
assert "policies" not in sys.modules and "gymnasium" not in sys.modules, sorted(sys.modules)
print(json.dumps(out))
"""
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                            cwd=Path(__file__).resolve().parents[1])
    assert result.returncode == 0, result.stderr
    policy = CheckpointPolicy.load(runs["hrl-sac"])
    for actions, goals in json.loads(result.stdout):
        np.testing.assert_allclose(actions, policy.act(obs), rtol=0, atol=ACTION_TOLERANCE)
        assert goals == policy.choose_goals(obs[:, :META_OBS_DIM]).tolist()


def test_torchscript_deprecation_warning_is_silenced_and_nothing_else(runs, tmp_path):
    policy = CheckpointPolicy.load(runs["sac"])
    path = tmp_path / "policy.pt"
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message=TORCHSCRIPT_DEPRECATION, category=DeprecationWarning)
        path.write_bytes(artifact_bytes(policy_module(policy), build_manifest(policy, "torchscript", "0" * 64)))
        load_policy(path)
    with pytest.warns(DeprecationWarning, match="something else"), torchscript_calls():
        warnings.warn("something else is deprecated", DeprecationWarning)


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
