"""A trained policy loaded from a training checkpoint, acting deterministically (evaluation, export)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from autonomy.observation import META_OBS_DIM, OBS_DIM
from missions.goals import GOAL_NAMES
from policies.config import TrainConfig
from policies.discrete_sac import DiscreteSAC
from policies.env_core import ACTION_HIGH, ACTION_LOW
from policies.normalizer import RunningMeanStd
from policies.sac import SAC
from policies.train import CHECKPOINT


def checkpoint_file(path: Path | str) -> Path:
    """The checkpoint file of a run folder (its checkpoint.pt) or the file itself; it must exist."""
    path = Path(path)
    if path.is_dir():
        path = path / CHECKPOINT
    if not path.exists():
        raise FileNotFoundError(f"no checkpoint at {path}")
    return path


@dataclass
class CheckpointPolicy:
    """Normaliser + low-level (or flat) actor + meta-controller (HRL-SAC) of one checkpoint."""

    config: TrainConfig
    normalizer: RunningMeanStd
    low: SAC
    meta: DiscreteSAC | None
    step: int
    path: Path

    @classmethod
    def load(cls, path: Path | str) -> "CheckpointPolicy":
        """From a checkpoint file or a run folder (its checkpoint.pt)."""
        path = checkpoint_file(path)
        return cls.from_state(torch.load(path, map_location="cpu", weights_only=False), path)

    @classmethod
    def from_state(cls, state: dict, path: Path) -> "CheckpointPolicy":
        """From a checkpoint already read with ``torch.load`` (``path`` is where it came from)."""
        policy = cls.untrained(TrainConfig.from_dict(state["config"]))
        policy.normalizer.load_state_dict(state["normalizer"])
        policy.low.load_state_dict(state["low"])
        if policy.meta is not None:
            policy.meta.load_state_dict(state["meta"])
        policy.step, policy.path = int(state["step"]), path
        return policy

    @classmethod
    def untrained(cls, config: TrainConfig) -> "CheckpointPolicy":
        """The networks a run with ``config`` starts from and an identity normaliser (benchmarks, tests)."""
        low = SAC(OBS_DIM, 4, ACTION_LOW, ACTION_HIGH, config, seed=config.seed)
        meta = None
        if config.algo == "hrl-sac":
            meta = DiscreteSAC(META_OBS_DIM, len(GOAL_NAMES), config, seed=config.seed + 1)
        return cls(config, RunningMeanStd((OBS_DIM,)), low, meta, 0, Path("untrained"))

    @property
    def hierarchical(self) -> bool:
        return self.meta is not None

    def act(self, obs: np.ndarray) -> np.ndarray:
        """(N, 276) raw observations -> (N, 4) deterministic actions in the environment's ranges."""
        return self.low.act(self.normalizer.normalize(obs), deterministic=True)

    def choose_goals(self, meta_obs: np.ndarray) -> np.ndarray:
        """(N, 272) raw meta observations -> (N,) goal indices (the most probable goal)."""
        return self.meta.act(self.normalizer.normalize(meta_obs), deterministic=True)
