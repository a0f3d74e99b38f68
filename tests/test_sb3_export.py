"""Bringing your own policy: a Stable-Baselines3 SAC trained on SarSearch-v1, exported by ``hrlsac export --from-sb3``
into the artifact flat SAC exports produce, acts as SB3's own ``predict`` and flies the demo mission through the
runner; whatever cannot be flown is refused in one line, with nothing written."""
from __future__ import annotations

import hashlib
import json
import sys
import zipfile
from pathlib import Path

import gymnasium
import numpy as np
import pytest
import torch
from cli_harness import assert_clean_error, run_cli

import policies  # noqa: F401  (registers SarSearch-v1 with gymnasium)
from autonomy.observation import NO_GOAL, OBS_DIM
from autonomy.policy import load_policy
from autonomy.policy_manifest import ObservationSpec
from missions.mission import FlightSettings
from policies.env.core import SarSearchConfig
from policies.env.gym_env import SarSearchEnv
from policies.evaluation.episodes import episode_batch
from policies.export import sb3 as sb3_export
from policies.export.parity import fly_and_record

sb3 = pytest.importorskip("stable_baselines3")

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "missions" / "library" / "demo.yaml"
FLAT_SAC = ROOT / "policies" / "pretrained" / "sac.pt"
ENV_KWARGS = {"action_frame": "arrive"}  # the shipped flat SAC's frame
STEPS = 300


def single_threaded(make):
    """``make()`` with one torch thread (tiny networks; a shared machine's other work makes more threads slower)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return make()
    finally:
        torch.set_num_threads(threads)


@pytest.fixture(scope="module")
def model_zip(tmp_path_factory) -> Path:
    """A few hundred steps of SB3 SAC on SarSearch-v1 in the arrive frame: a model, not a good policy."""
    def train() -> Path:
        env = gymnasium.make("SarSearch-v1", **ENV_KWARGS)
        model = sb3.SAC("MlpPolicy", env, learning_starts=100, buffer_size=1_000, batch_size=32, seed=0,
                        policy_kwargs={"net_arch": [32, 32]}, device="cpu")
        model.learn(total_timesteps=STEPS)
        path = tmp_path_factory.mktemp("sb3") / "model.zip"
        model.save(path)
        return path

    return single_threaded(train)


@pytest.fixture(scope="module")
def exported(model_zip, tmp_path_factory) -> tuple[Path, str]:
    """The model exported through the command line, and what the command printed."""
    out = tmp_path_factory.mktemp("artifact") / "sb3.pt"
    result = single_threaded(lambda: run_cli("export", "--from-sb3", str(model_zip), "-o", str(out),
                                             "--env-kwargs", json.dumps(ENV_KWARGS)))
    assert result.code == 0, result.err
    return out, result.out


def test_the_artifact_declares_what_the_flat_sac_artifact_declares(model_zip, exported):
    path, printed = exported
    manifest, flat = load_policy(path).manifest, load_policy(FLAT_SAC).manifest
    assert manifest.algorithm == "sb3-sac" and manifest.format == "torchscript"
    assert manifest.subgoal_interval is None and manifest.goals == () and not manifest.hierarchical
    for field in ("format_version", "observation", "action", "entry_points", "precision", "action_tolerance"):
        assert getattr(manifest, field) == getattr(flat, field), field  # sac.pt is in the arrive frame too
    assert manifest.observation == ObservationSpec.current()
    config = manifest.training_config
    assert (config["task"], config["action_frame"]) == ("SarSearch-v1", "arrive")
    assert config["flight"] == flat.training_config["flight"]  # the environment's defaults, which sac.pt had
    assert config["trainer"] == f"stable-baselines3 {sb3.__version__}" and config["seed"] == 0
    assert config["stable_baselines3"]["net_arch"] == [32, 32] and config["env_kwargs"] == ENV_KWARGS
    source = manifest.source_checkpoint
    assert source.file == "model.zip" and source.trained_steps == STEPS
    assert source.sha256 == hashlib.sha256(model_zip.read_bytes()).hexdigest()
    assert "parity with Stable-Baselines3's predict: 10,000 observations" in printed and ": ok" in printed
    assert "trained: stable-baselines3" in printed


@pytest.mark.parametrize("fmt", ["torchscript", "torch-export"])
def test_the_artifact_acts_as_sb3_predict_on_observations_of_the_environment(model_zip, exported, fmt, tmp_path):
    model = sb3.SAC.load(model_zip, device="cpu")
    if fmt == "torchscript":
        artifact = load_policy(exported[0])
    else:
        artifact = load_policy(sb3_export.export_sb3_policy(model_zip, tmp_path / "sb3.pt2", fmt, ENV_KWARGS,
                                                            observations=500).path)

    def predict(obs: np.ndarray) -> np.ndarray:
        return model.predict(obs, deterministic=True)[0]

    core = episode_batch("test", 20, FlightSettings(), goal_conditioned=False, action_frame="arrive")
    obs = fly_and_record(core, predict, count=2_000, seed=3)  # the test split: not what the export checked on
    assert obs.shape == (2_000, OBS_DIM)
    expected = predict(obs)
    assert np.abs(artifact.act(obs) - expected).max() <= 1e-6
    assert expected.std(axis=0).min() > 0  # the actions vary with the observation: a real comparison
    assert (artifact.select_goal(obs[:, :-4]) == NO_GOAL).all()
    for row in obs[:3]:  # one observation at a time, as the runner calls it
        np.testing.assert_allclose(artifact.act(row), predict(row), atol=1e-6, rtol=0)


def test_the_demo_mission_flies_with_the_sb3_artifact(exported, tmp_path):
    path, _ = exported
    result = run_cli("mission", "replay", str(DEMO), "--policy", str(path), "--out", str(tmp_path), "--no-video",
                     "--quiet")
    assert result.code == 0, result.err
    assert "demo (sb3-sac)" in result.out
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["pilot"] == "sb3-sac" and report["policy"] == str(path)
    assert report["policy_sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    assert report["search_end"] in ("victim reached", "step limit", "return to base", "bingo failsafe")
    assert report["outcome"]["outcome"] == "completed"
    assert report["outcome"]["vehicle_end"] == "landed and disarmed"
    assert report["steps"] >= 1 and report["setpoints_sent"] > 20 * report["steps"]


# --------------------------------------------------------------------------------------------------- refusals
def other_models(folder: Path) -> dict[str, Path]:
    """Model zips that must be refused, each saved by SB3 itself: PPO, SAC on SarSearch-v0, SAC on a
    VecNormalize-wrapped SarSearch-v1 (its last training observation normalised)."""
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    made = {"ppo": sb3.PPO("MlpPolicy", gymnasium.make("SarSearch-v1"), n_steps=64, batch_size=32, device="cpu",
                           policy_kwargs={"net_arch": [8]}),
            "v0": sb3.SAC("MlpPolicy", SarSearchEnv(SarSearchConfig(task="SarSearch-v0")), buffer_size=100,
                          device="cpu", policy_kwargs={"net_arch": [8]})}
    normalised = VecNormalize(DummyVecEnv([lambda: gymnasium.make("SarSearch-v1")]))
    made["vecnormalize"] = sb3.SAC("MlpPolicy", normalised, learning_starts=1_000, buffer_size=100, device="cpu",
                                   policy_kwargs={"net_arch": [8]})
    made["vecnormalize"].learn(total_timesteps=30)  # random warm-up steps only: no update
    paths = {}
    for name, model in made.items():
        paths[name] = folder / f"{name}.zip"
        model.save(paths[name])
    return paths


@pytest.fixture(scope="module")
def bad_inputs(model_zip, tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("bad")
    paths = single_threaded(lambda: other_models(folder))
    paths["text"] = folder / "notes.zip"
    paths["text"].write_text("not a zip\n")
    paths["truncated"] = folder / "truncated.zip"
    paths["truncated"].write_bytes(model_zip.read_bytes()[:2_000])
    paths["corrupt"] = folder / "corrupt.zip"
    with zipfile.ZipFile(paths["corrupt"], "w") as archive:  # the members model.save writes, but garbage
        archive.writestr("data", "{not json")
        archive.writestr("policy.pth", b"\0" * 16)
    paths["artifact"] = FLAT_SAC  # an hrlsac artifact is a zip too
    paths["missing"] = folder / "nope.zip"
    return paths


@pytest.mark.parametrize("name, mentions", [
    ("missing", ["nope.zip: no such file"]),
    ("text", ["notes.zip: not a Stable-Baselines3 model zip (not a readable zip archive)"]),
    ("truncated", ["truncated.zip: not a Stable-Baselines3 model zip"]),
    ("corrupt", ["corrupt.zip: the Stable-Baselines3 model does not load"]),
    ("artifact", ["sac.pt: not a Stable-Baselines3 model zip (no data or policy.pth inside"]),
    ("ppo", ["ppo.zip: not a SAC model (its policy is ActorCriticPolicy"]),
    ("v0", ["v0.zip: the model's observation space is a Box of shape (276,) (SarSearch-v0's",
            "not SarSearch-v1's (288 values"]),
    ("vecnormalize", ["vecnormalize.zip: the model was trained on normalised observations", "VecNormalize"]),
])
def test_a_model_that_cannot_be_flown_is_one_line_and_nothing_is_written(bad_inputs, name, mentions, tmp_path):
    result = run_cli("export", "--from-sb3", str(bad_inputs[name]), "-o", str(tmp_path / "out.pt"))
    assert_clean_error(result, *mentions)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("args, mentions", [
    (["--env-kwargs", '{"goal_conditioned": true}'], ["goal_conditioned must be false"]),
    (["--env-kwargs", '{"task": "SarSearch-v0"}'], ["task 'SarSearch-v0' cannot be flown"]),
    (["--env-kwargs", '{"render": 1}'], ["'render' is not accepted (choose from task, split"]),
    (["--env-kwargs", '{"flight": {"max_steps": 1}}'], ["env kwargs:", "max_steps"]),
    (["--env-kwargs", '{"action_frame": "sideways"}'], ["env kwargs:", "sideways"]),
    (["--env-kwargs", "[1]"], ["--env-kwargs must be a JSON object"]),
    (["--env-kwargs", "{"], ["--env-kwargs is not valid JSON"]),
    (["--precision", "int8"], ["--precision int8 is for hrlsac checkpoints"]),
    (["runs/x"], ["give exactly one of CHECKPOINT and --from-sb3 MODEL.zip"]),
])
def test_bad_export_options_are_one_line(model_zip, args, mentions, tmp_path):
    result = run_cli("export", "--from-sb3", str(model_zip), "-o", str(tmp_path / "out.pt"), *args)
    assert_clean_error(result, *mentions)
    assert list(tmp_path.iterdir()) == []


def test_without_stable_baselines3_the_error_says_how_to_install_it(model_zip, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "stable_baselines3", None)  # import stable_baselines3 now fails
    result = run_cli("export", "--from-sb3", str(model_zip), "-o", str(tmp_path / "out.pt"))
    assert_clean_error(result, "needs stable_baselines3: pip install stable-baselines3")
    assert list(tmp_path.iterdir()) == []


def test_an_artifact_that_disagrees_with_predict_is_not_written(model_zip, tmp_path, monkeypatch):
    exact = sb3_export.sb3_module

    def off_by_a_little(model):
        module = exact(model)
        module.action_head.low += 1e-3  # every action 0.001 off SB3's
        return module

    monkeypatch.setattr(sb3_export, "sb3_module", off_by_a_little)
    full_check = sb3_export.sb3_parity  # on 1,000 observations instead of 10,000: the difference is everywhere
    monkeypatch.setattr(sb3_export, "sb3_parity", lambda model, artifact, config, count: full_check(
        model, artifact, config, 1_000))
    result = run_cli("export", "--from-sb3", str(model_zip), "-o", str(tmp_path / "out.pt"))
    assert_clean_error(result, "parity check with Stable-Baselines3's predict failed", "1,000 observations",
                       "max |action difference| 1.0e-03", code=1)
    assert list(tmp_path.iterdir()) == []
