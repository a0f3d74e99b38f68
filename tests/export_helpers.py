"""What the policy-export tests share (tests/test_export_*.py): short training runs of both algorithms, their
artifacts in both formats and the observations their policies flew through, each built once per test process (no
test keeps a change to them), and the one-line error a refused artifact gives. Not a test module (pytest does not
collect it)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from autonomy.policy import PolicyArtifactError, load_policy
from missions.mission import FlightSettings
from policies.checkpoint import CheckpointPolicy
from policies.config import NetworkConfig, TrainConfig
from policies.export.artifact import export_policy
from policies.export.parity import record_observations
from policies.training.trainer import Trainer


ALGOS = ("hrl-sac", "sac")
FORMATS = ("torchscript", "torch-export")
K = 10
# Small networks, but every kind of layer the presets use: LayerNorm, Dropout (must be off), the extra head layer.
NET = NetworkConfig(hidden=(32, 32), head=16, dropout=0.1)


_BUILT: dict[str, dict] = {}
"""What the expensive builders below made, by name: once per test process, shared by the export test files."""


def trained_runs(tmp_path_factory) -> dict[str, Path]:
    """A few hundred training steps of each algorithm (parity needs a checkpoint, not a good policy); flat SAC's
    with an action margin, so that its artifact must clip as the eager policy does. Built once per test process;
    a test that writes into a run folder removes what it wrote."""
    if "runs" not in _BUILT:
        out = {}
        for algo in ALGOS:
            config = TrainConfig.from_preset(
                "default", algo=algo, seed=1, total_steps=400, num_envs=2, warmup_steps=100, batch_size=32,
                meta_batch_size=8, buffer_size=2_000, meta_buffer_size=500, checkpoint_every=10**6, log_every=10**6,
                eval_every=0, actor=NET, critic=NET, meta_actor=NET, meta_critic=NET,
                flight=FlightSettings(max_steps=120, subgoal_interval=K), action_margin=0.25 if algo == "sac" else 0.0)
            out[algo] = tmp_path_factory.mktemp(algo)
            Trainer(config, out[algo]).run(progress=False)
        _BUILT["runs"] = out
    return _BUILT["runs"]


def exported_artifacts(runs: dict[str, Path], tmp_path_factory) -> dict[tuple[str, str], Path]:
    """Each run exported in each format, once per test process."""
    if "artifacts" not in _BUILT:
        folder = tmp_path_factory.mktemp("artifacts")
        _BUILT["artifacts"] = {(algo, fmt): export_policy(runs[algo], folder / f"{algo}-{fmt}.pt", fmt).path
                               for algo in ALGOS for fmt in FORMATS}
    return _BUILT["artifacts"]


def recorded_observations(runs: dict[str, Path]) -> dict[str, np.ndarray]:
    """Observations each run's policy flew through (policies.export.parity.record_observations), once per test
    process."""
    if "recorded" not in _BUILT:
        _BUILT["recorded"] = {algo: record_observations(CheckpointPolicy.load(runs[algo])) for algo in ALGOS}
    return _BUILT["recorded"]


def single_line_error(path: Path, match: str) -> str:
    with pytest.raises(PolicyArtifactError, match=match) as info:
        load_policy(path)
    message = str(info.value)
    assert isinstance(info.value, ValueError) and "\n" not in message and message.startswith(str(path))
    return message
