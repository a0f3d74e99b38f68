"""The training loop's exact resume: a run killed after a checkpoint and resumed equals an uninterrupted one (flat
and hierarchical, and inside the meta-only phase), a terminated ``hrlsac train`` saves its checkpoint and resumes,
and checkpoints pickled under the environments' old module names still load."""
from __future__ import annotations

import json
import pickle
import subprocess
import sys

import numpy as np
import pytest
import torch
from training_helpers import log_rows, small_config

from policies.config import TrainConfig
from policies.evaluation.parallel import quick_evaluation
from policies.training.trainer import Trainer


@pytest.mark.parametrize("algo", ["sac", "hrl-sac"])
def test_resuming_after_a_kill_continues_exactly(tmp_path, algo):
    config = small_config(algo)
    uninterrupted = Trainer(config, tmp_path / "a")
    uninterrupted.run(progress=False)
    killed = Trainer(config, tmp_path / "b")
    killed.run(progress=False, stop_at=400)  # the checkpoint at step 400 is all that survives the kill
    resumed = Trainer(config, tmp_path / "b", resume=True)
    assert resumed.step == 400
    resumed.run(progress=False)
    for a, b in zip(uninterrupted.low.actor.state_dict().values(), resumed.low.actor.state_dict().values()):
        assert torch.equal(a, b)
    for a, b in zip(uninterrupted.low.critic.state_dict().values(), resumed.low.critic.state_dict().values()):
        assert torch.equal(a, b)
    if algo == "hrl-sac":
        for a, b in zip(uninterrupted.meta.actor.state_dict().values(), resumed.meta.actor.state_dict().values()):
            assert torch.equal(a, b)
    assert uninterrupted.episodes == resumed.episodes and uninterrupted.episodes > 0
    assert log_rows(tmp_path / "a" / "progress.csv") == log_rows(tmp_path / "b" / "progress.csv")
    np.testing.assert_array_equal(uninterrupted.obs, resumed.obs)


def test_a_terminated_training_saves_its_checkpoint_and_resumes(tmp_path):
    import signal
    import time

    run = tmp_path / "run"
    base = [sys.executable, "-m", "hrlsac_cli", "train"]
    process = subprocess.Popen([*base, "--algo", "sac", "--steps", "1000000", "--out", str(run), "--quiet",
                                "--set", "warmup_steps=100", "--set", "num_envs=2", "--set", "log_every=100"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not (run / "progress.csv").exists():
        time.sleep(0.2)
    while time.monotonic() < deadline and len((run / "progress.csv").read_text().splitlines()) < 3:
        time.sleep(0.2)
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, stderr
    assert "checkpoint saved" in stderr and "--resume" in stderr
    state = torch.load(run / "checkpoint.pt", map_location="cpu", weights_only=False)
    assert state["step"] >= 200
    resumed = Trainer(TrainConfig.from_dict(json.loads((run / "config.json").read_text())), run, resume=True)
    assert resumed.step == state["step"]


def test_the_meta_only_phase_resumes_exactly(tmp_path):
    config = small_config("hrl-sac", total_steps=1_200, meta_only_steps=600, checkpoint_every=400,
                          meta_keep_best=True, eval_every=200, eval_episodes=4)
    uninterrupted = Trainer(config, tmp_path / "a", evaluate=quick_evaluation)
    uninterrupted.run(progress=False)
    killed = Trainer(config, tmp_path / "b", evaluate=quick_evaluation)
    killed.run(progress=False, stop_at=800)  # killed inside the phase, after the checkpoint at step 800
    resumed = Trainer(config, tmp_path / "b", resume=True, evaluate=quick_evaluation)
    assert resumed.step == 800 and resumed.low_level_frozen
    resumed.run(progress=False)
    for a, b in zip(uninterrupted.meta.critic.state_dict().values(), resumed.meta.critic.state_dict().values()):
        assert torch.equal(a, b)
    for a, b in zip(uninterrupted.meta.actor.state_dict().values(), resumed.meta.actor.state_dict().values()):
        assert torch.equal(a, b)
    assert uninterrupted.best["step"] == resumed.best["step"]
    assert log_rows(tmp_path / "a" / "progress.csv") == log_rows(tmp_path / "b" / "progress.csv")


def test_a_checkpoint_written_before_the_sub_packages_still_resumes(tmp_path):
    """Checkpoints pickle the environments' state, naming their classes' modules; those written when the core was
    ``policies.env_core`` (and the v1 task ``policies.ambiguous_env``) load into today's modules."""
    from policies.checkpoint import load_environment

    trainer = Trainer(small_config("hrl-sac"), tmp_path)
    pickled = pickle.dumps(trainer.env.core)
    # protocol 2 names each class as text ("module\nname\n"), so the old names may differ in length
    old = pickle.dumps(trainer.env.core, protocol=2).replace(b"policies.env.core\n", b"policies.env_core\n")
    old = old.replace(b"policies.env.task_v1\n", b"policies.ambiguous_env\n")
    assert b"policies.env_core\n" in old and b"policies.ambiguous_env\n" in old and b"policies.env.core\n" not in old
    assert pickle.dumps(load_environment(old)) == pickled
