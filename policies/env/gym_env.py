"""``SarSearch-v0`` and ``SarSearch-v1``: the gymnasium environment (one search episode at a time).

A thin wrapper around the task's core (:class:`policies.env.task_v0.SarSearchBatch` or
:class:`policies.env.task_v1.AmbiguousSearchBatch`) with N = 1; the vectorised
:class:`policies.env.vector.SarSearchVectorEnv` drives the same core, so both give the same results for the
same seeds. See ``docs/environment.md`` for the world scale and the task modules for the step.
"""
from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from missions.render import render_search
from policies.env.core import ACTION_HIGH, ACTION_LOW, SarSearchConfig, next_episode_seed
from policies.env.tasks import new_batch


class SarSearchEnv(gym.Env):
    """Maritime search: find and reach the victim; see the module docstring of ``policies.env.core``."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, config: SarSearchConfig | None = None, render_mode: str | None = None, **overrides: Any):
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if overrides:  # gymnasium.make("SarSearch-v1", split="test", goal_conditioned=True)
            config = SarSearchConfig(**{**(config.__dict__ if config else {}), **overrides})
        self.config = config or SarSearchConfig()
        self.render_mode = render_mode
        self.core = new_batch(self.config, 1)
        self.observation_space = gym.spaces.Box(self.core.layout.low, self.core.layout.high, dtype=np.float32)
        self.action_space = gym.spaces.Box(ACTION_LOW, ACTION_HIGH, dtype=np.float32)
        self._seed: int | None = None
        self._path: list[tuple[float, float]] = []

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if seed is not None:
            episode_seed = int(seed)
        elif self._seed is None:  # never seeded: draw one from gymnasium's generator
            episode_seed = int(self.np_random.integers(0, 2**63 - 1))
        else:
            episode_seed = int(next_episode_seed(np.array([self._seed], dtype=np.uint64))[0])
        self._seed = episode_seed
        self.core.reset([0], [episode_seed])
        obs = self.core.obs[0].copy()
        self._path = [tuple(self.core.position[0])]
        return obs, {"scenario": self.core.scenarios[0].name, "episode_seed": episode_seed}

    def step(self, action):
        obs, reward, terminated, truncated, info = self.core.step(np.asarray(action, dtype=np.float64)[None, :])
        self._path.append(tuple(self.core.position[0]))
        single_info = {key: (value[0].copy() if value.ndim > 1 else value[0]) for key, value in info.items()}
        return obs[0].copy(), float(reward[0]), bool(terminated[0]), bool(truncated[0]), single_info

    def set_goal(self, goal: int) -> np.ndarray:
        """HRL-SAC: the meta-controller's goal for the next K steps (an index into GOAL_NAMES).

        Returns the current observation updated with the goal (its one-hot and, in goal-conditioned mode,
        the goal's point as the target)."""
        self.core.set_goals(np.array([goal]))
        return self.core.obs[0].copy()

    @property
    def meta_observation(self) -> np.ndarray:
        return self.core.meta_observation[0].copy()

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        return render_search(self.core, 0, self._path, float(self.core.last_action[0, 3]))
