"""``SarSearchVectorEnv``: N search episodes stepped together with numpy (gymnasium ``VectorEnv``).

Same core as the single environment (the task's core, ``policies.env.tasks``), so for the same seeds both give
identical episodes.
Auto-reset happens in the same step (gymnasium's ``AutoresetMode.SAME_STEP``): when episode i ends,
``obs[i]`` is already the first observation of its next episode, ``info["final_obs"][i]`` holds the last
observation of the one that ended (``info["_final_obs"][i]`` is True), and the other info entries describe
the step just taken. The next episode's seed is ``next_episode_seed(seed)``, exactly what the single
environment uses on ``reset()`` without a seed.
"""
from __future__ import annotations

from typing import Sequence

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv

from policies.env.core import ACTION_HIGH, ACTION_LOW, SarSearchConfig, next_episode_seed
from policies.env.tasks import new_batch


class SarSearchVectorEnv(VectorEnv):
    """N maritime searches at once."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(self, num_envs: int, config: SarSearchConfig | None = None, **overrides):
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        if overrides:  # gymnasium.make_vec("SarSearch-v1", num_envs=64, vectorization_mode="vector_entry_point")
            config = SarSearchConfig(**{**(config.__dict__ if config else {}), **overrides})
        self.config = config or SarSearchConfig()
        self.num_envs = num_envs
        self.core = new_batch(self.config, num_envs)
        self.single_observation_space = gym.spaces.Box(self.core.layout.low, self.core.layout.high, dtype=np.float32)
        self.single_action_space = gym.spaces.Box(ACTION_LOW, ACTION_HIGH, dtype=np.float32)
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, num_envs)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, num_envs)

    def reset(self, *, seed: int | Sequence[int] | None = None, options: dict | None = None):
        if seed is None:
            seeds = np.random.default_rng().integers(0, 2**63 - 1, size=self.num_envs)
        elif isinstance(seed, (int, np.integer)):
            seeds = [int(seed) + i for i in range(self.num_envs)]  # gymnasium's convention
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"reset: expected {self.num_envs} seeds, got {len(seeds)}")
        self.core.reset(np.arange(self.num_envs), np.asarray(seeds, dtype=np.uint64))
        return self.core.obs.copy(), {"episode_seed": self.core.episode_seed.copy()}

    def step(self, actions):
        obs, reward, terminated, truncated, info = self.core.step(np.asarray(actions))
        info = {key: value.copy() for key, value in info.items()}  # the core's are live views
        done = terminated | truncated
        if done.any():
            finished = np.flatnonzero(done)
            final_obs = np.full(self.num_envs, None, dtype=object)
            final_obs[finished] = list(obs[finished])  # copies: rows of a fancy index
            info["final_obs"], info["_final_obs"] = final_obs, done.copy()
            self.core.reset(finished, next_episode_seed(self.core.episode_seed[finished]))
        return self.core.obs.copy(), reward, terminated, truncated, info

    def set_goals(self, goals: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """HRL-SAC: give the environments in ``mask`` (all by default) a new meta-controller goal; returns the
        observations updated with it."""
        self.core.set_goals(goals, mask)
        return self.core.obs.copy()

    @property
    def step_reward(self) -> float:
        """The environment reward's constant per-step part (SarSearch-v0's -0.1, v1's 0): the learning rewards
        (``policies.env.shaping``) leave it out."""
        return self.core.step_reward

    @property
    def meta_observation(self) -> np.ndarray:
        return self.core.meta_observation.copy()
