"""What the SAC agents' tests share (tests/test_sac_*.py): action ranges, small configs, batches of transitions and
constant networks. Not a test module (pytest does not collect it)."""
from __future__ import annotations

import dataclasses

import numpy as np
import torch
from torch import nn

from policies.agents.discrete_sac import DiscreteSacConfig
from policies.agents.replay_batch import ReplayBatch
from policies.agents.sac import SacConfig
from policies.config import NetworkConfig, TrainConfig


ENV_LOW = np.array([-1.0, -1.0, 0.0, 0.0], dtype=np.float32)
ENV_HIGH = np.array([1.0, 1.0, 1.0, 1.0], dtype=np.float32)
LOW2 = np.array([-1.0, 0.0], dtype=np.float32)
HIGH2 = np.array([1.0, 1.0], dtype=np.float32)


def small_config(dropout: float = 0.0, **overrides) -> TrainConfig:
    net = NetworkConfig(hidden=(32, 32), layer_norm=True, dropout=dropout)
    return TrainConfig(actor=net, critic=net, meta_actor=net, meta_critic=net, **overrides)


def as_sac(config: TrainConfig) -> SacConfig:
    return SacConfig.from_train_config(config)


def as_meta(config: TrainConfig) -> DiscreteSacConfig:
    return DiscreteSacConfig.from_train_config(config)


def constant_output(seq: nn.Sequential, value) -> None:
    """Zero the last Linear's weights and set its bias: the network then outputs ``value`` for every input."""
    last = seq[-1]
    with torch.no_grad():
        last.weight.zero_()
        last.bias.copy_(torch.as_tensor(value, dtype=torch.float32).expand_as(last.bias))


def continuous_batch(rng: np.random.Generator, b: int, obs_dim: int = 3, low=LOW2, high=HIGH2, done=None
                     ) -> ReplayBatch:
    return ReplayBatch(
        obs=rng.standard_normal((b, obs_dim)).astype(np.float32),
        action=rng.uniform(low, high, (b, len(low))).astype(np.float32),
        reward=rng.standard_normal(b).astype(np.float32),
        next_obs=rng.standard_normal((b, obs_dim)).astype(np.float32),
        done=(rng.random(b) < 0.3).astype(np.float32) if done is None else np.full(b, done, np.float32),
    )


def discrete_batch(rng: np.random.Generator, b: int, obs_dim: int = 3, n: int = 3) -> ReplayBatch:
    return ReplayBatch(
        obs=rng.standard_normal((b, obs_dim)).astype(np.float32),
        action=rng.integers(0, n, b),
        reward=rng.standard_normal(b).astype(np.float32),
        next_obs=rng.standard_normal((b, obs_dim)).astype(np.float32),
        done=(rng.random(b) < 0.3).astype(np.float32),
        discount=(0.99 ** rng.integers(1, 31, b)).astype(np.float32),
    )


def weighted(batch: ReplayBatch, weights: np.ndarray) -> ReplayBatch:
    return dataclasses.replace(batch, weights=weights)
