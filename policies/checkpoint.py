"""Training checkpoints: the file (written atomically, read with one clear error), the pickled environments in it,
and the trained policy loaded from one, acting deterministically (evaluation, export). Training writes them;
evaluation and export read them; this module imports neither."""
from __future__ import annotations

import io
import os
import pickle
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np
import torch

from autonomy.policy import one_line
from missions.goals import GOAL_NAMES
from policies.agents.discrete_sac import DiscreteSAC, DiscreteSacConfig
from policies.agents.normalizer import RunningMeanStd
from policies.agents.sac import SAC, SacConfig
from policies.config import TrainConfig
from policies.env.core import ACTION_HIGH, ACTION_LOW

CHECKPOINT = "checkpoint.pt"
"""The checkpoint file of a run folder."""

MOVED_MODULES = {"policies.env_core": "policies.env.core", "policies.ambiguous_env": "policies.env.task_v1",
                 "policies.env.ambiguous": "policies.env.task_v1",
                 "policies.env.baselines": "missions.searchers",
                 "missions.search_state": "missions.search_state_v0",
                 "missions.belief_search": "missions.search_state_v1", "missions.signing": "mavlink_signing"}
"""Where the classes of a pickled environment live now, for checkpoints written with an earlier module layout (their
pickles name the old modules)."""
MOVED_CLASSES = {("policies.env.core", "SarSearchBatch"): "policies.env.task_v0"}
"""Classes that left a module that still exists: (old module, class) -> the module that holds the class now."""


def atomic_torch_save(obj, path: Path) -> None:
    """Write ``obj`` with torch.save to a temporary file, then rename: a kill never leaves half a file."""
    tmp = path.with_name(path.name + ".tmp")
    torch.save(obj, tmp)
    os.replace(tmp, path)


class _EnvironmentUnpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str):
        module = MOVED_MODULES.get(module, module)
        return super().find_class(MOVED_CLASSES.get((module, name), module), name)


def dump_environment(core) -> bytes:
    """The environments' state as a checkpoint holds it (``"env"``)."""
    return pickle.dumps(core)


def load_environment(pickled: bytes):
    """The environments' state pickled in a checkpoint (``"env"``), whichever module layout wrote it."""
    return _EnvironmentUnpickler(io.BytesIO(pickled)).load()


def new_agents(config: TrainConfig) -> tuple[SAC, DiscreteSAC | None]:
    """The agents a run with ``config`` starts from: the continuous SAC (HRL-SAC's low level, or the flat SAC) and,
    for HRL-SAC, the meta-controller, each with its settings taken from ``config``."""
    layout = config.layout
    low = SAC(layout.dim, 4, ACTION_LOW, ACTION_HIGH, SacConfig.from_train_config(config), seed=config.seed,
              input_mask=config.low_level_input_mask)
    meta = None
    if config.algo == "hrl-sac":
        meta = DiscreteSAC(layout.meta_dim, len(GOAL_NAMES), DiscreteSacConfig.from_train_config(config),
                           seed=config.seed + 1, input_mask=config.meta_input_mask)
    return low, meta


def checkpoint_file(path: Path | str) -> Path:
    """The checkpoint file of a run folder (its checkpoint.pt) or the file itself; it must exist."""
    path = Path(path)
    if path.is_dir():
        path = path / CHECKPOINT
    if not path.exists():
        raise FileNotFoundError(f"no checkpoint at {path}")
    return path


CHECKPOINT_KEYS = ("config", "normalizer", "low", "step")
"""Entries every training checkpoint holds (``meta`` too for HRL-SAC); their absence means another kind of file."""


def load_checkpoint_state(source: BinaryIO | Path, path: Path) -> dict:
    """``torch.load`` of a training checkpoint (an open file or a path); whatever is wrong with the file is one
    ValueError naming ``path``, with a hint when it is a policy artifact rather than a checkpoint."""
    if _is_policy_artifact(source):  # refused before torch.load, which would hand it on to torch.jit.load
        raise ValueError(f"{path}: not a readable training checkpoint: it is a policy artifact ('hrlsac policy info' "
                         "reads it); give the training checkpoint (checkpoint.pt of the run folder) instead")
    try:
        state = torch.load(source, map_location="cpu", weights_only=False)
    except Exception as exc:  # torch.load raises anything from UnpicklingError to RuntimeError on a bad file
        problem = one_line(exc)
    else:
        if not isinstance(state, dict):
            problem = f"it holds a {type(state).__name__}, not a checkpoint's dict"
        else:
            missing = [key for key in CHECKPOINT_KEYS if key not in state]
            if not missing:
                return state
            problem = f"no {', '.join(map(repr, missing))} in it"
    raise ValueError(f"{path}: not a readable training checkpoint ({problem})")


def _is_policy_artifact(source: BinaryIO | Path) -> bool:
    """Whether the file is a zip holding a manifest.json, i.e. what ``hrlsac export`` writes."""
    try:
        with zipfile.ZipFile(source) as archive:
            return any(name.endswith("extra/manifest.json") for name in archive.namelist())
    except Exception:  # not a zip, or a damaged one: not an artifact either way (torch.load will say more)
        return False
    finally:
        if not isinstance(source, Path):
            source.seek(0)  # torch.load reads the same handle next


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
        """From a checkpoint file or a run folder (its checkpoint.pt); ValueError if it is not a checkpoint."""
        path = checkpoint_file(path)
        with path.open("rb") as handle:
            return cls.read(handle, path)

    @classmethod
    def read(cls, handle: BinaryIO, path: Path) -> "CheckpointPolicy":
        """From an open checkpoint file; any problem with its bytes is one ValueError naming ``path``."""
        state = load_checkpoint_state(handle, path)
        try:
            return cls.from_state(state, path)
        except Exception as exc:  # a state dict of other networks or config fields: anything from KeyError up
            raise ValueError(f"{path}: not a readable training checkpoint ({one_line(exc)})") from None

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
        low, meta = new_agents(config)
        return cls(config, RunningMeanStd((config.layout.dim,)), low, meta, 0, Path("untrained"))

    @property
    def hierarchical(self) -> bool:
        return self.meta is not None

    def act(self, obs: np.ndarray) -> np.ndarray:
        """(N, obs_dim) raw observations -> (N, 4) deterministic actions in the environment's ranges."""
        return self.low.act(self.normalizer.normalize(obs), deterministic=True)

    def choose_goals(self, meta_obs: np.ndarray) -> np.ndarray:
        """(N, meta_dim) raw meta observations -> (N,) goal indices (the most probable goal)."""
        return self.meta.act(self.normalizer.normalize(meta_obs), deterministic=True)
