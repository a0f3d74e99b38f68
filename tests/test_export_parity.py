"""Policy export and the on-board runtime: parity with the eager policy on recorded observations (both formats, and
int8), clipping under an action margin, denormals flushed inside the runtime's calls only, plain torch loaders, a
failed parity check writing nothing, and the runtime (the hierarchy, without the training code, TorchScript's
deprecation warning silenced)."""
from __future__ import annotations

import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch
from export_helpers import ALGOS, FORMATS, K, recorded_observations

from autonomy.observation import META_OBS_DIM, OBS_DIM
from autonomy.policy import load_policy
from autonomy.policy_manifest import summary_lines
from autonomy.torch_compat import TORCHSCRIPT_DEPRECATION, torchscript_calls
from missions.goals import GOAL_NAMES, goal_due
from policies.checkpoint import CheckpointPolicy
from policies.export.artifact import ParityError, artifact_bytes, build_manifest, export_policy
from policies.export.module import PRECISIONS, policy_module
from policies.export.parity import ACTION_TOLERANCE, INT8_ACTION_TOLERANCE, TOLERANCES, Parity, check_parity


@pytest.fixture(scope="module")
def recorded(runs) -> dict[str, np.ndarray]:
    return recorded_observations(runs)


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
