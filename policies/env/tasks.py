"""The environment core of each task version: ``SarSearch-v0`` (``task_v0.py``, the paper's task) or
``SarSearch-v1`` (``task_v1.py``). Kept apart from both so that neither imports the other's dependant."""
from __future__ import annotations

from typing import Sequence

import numpy as np

from policies.env.core import SarSearchConfig
from policies.env.task_v0 import SarSearchBatch
from policies.env.task_v1 import AmbiguousSearchBatch


def batch_class(task: str) -> type:
    """The environment core of a task version."""
    return AmbiguousSearchBatch if task == "SarSearch-v1" else SarSearchBatch


def new_batch(config: SarSearchConfig, num_envs: int):
    """``num_envs`` environments of ``config.task`` (not reset yet)."""
    return batch_class(config.task)(config, num_envs)


def make_batch(config: SarSearchConfig, seeds: Sequence[int]):
    """A batch with every slot reset to its seed."""
    batch = new_batch(config, len(seeds))
    batch.reset(np.arange(len(seeds)), np.asarray(seeds, dtype=np.uint64))
    return batch
