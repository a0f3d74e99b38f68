"""n-step returns for the continuous SAC's replay: one-step transitions of N environments in, n-step ones out.

A transition stored for step t carries r_t + g r_(t+1) + ... + g^(k-1) r_(t+k-1), the observation after step
t+k-1 and the bootstrap discount g^k, with k = n, or fewer when the episode ended first (``done`` is then its
termination; a truncation still bootstraps, from the last real observation). As in Stable-Baselines3's and
CleanRL's n-step replay, the actions of steps t+1 .. t+k-1 are the behaviour policy's (no off-policy correction).
"""
from __future__ import annotations

import numpy as np

from policies.agents.replay_batch import ReplayBatch


class NStepReturns:
    """The pending steps of each environment; :meth:`add` returns the transitions they complete."""

    def __init__(self, n_step: int, gamma: float, num_envs: int):
        self.n_step, self.gamma = n_step, gamma
        self.pending: list[list[tuple[np.ndarray, np.ndarray, float]]] = [[] for _ in range(num_envs)]

    def add(self, obs: np.ndarray, actions: np.ndarray, rewards: np.ndarray, next_obs: np.ndarray,
            terminated: np.ndarray, done: np.ndarray) -> ReplayBatch | None:
        """One vector step (``next_obs``: the real next observations, not reset ones); returns the completed n-step
        transitions (float32, with their ``discount``), or None."""
        out: list[tuple] = []
        for i, steps in enumerate(self.pending):
            steps.append((obs[i].copy(), actions[i].copy(), float(rewards[i])))
            if done[i]:
                while steps:
                    out.append(self._transition(steps, next_obs[i], float(terminated[i])))
                    steps.pop(0)
            elif len(steps) == self.n_step:
                out.append(self._transition(steps, next_obs[i], 0.0))
                steps.pop(0)
        if not out:
            return None
        # the columns in ReplayBatch's order: obs, action, reward, next_obs, done, discount
        return ReplayBatch(*(np.stack(column).astype(np.float32) for column in zip(*out)))

    def _transition(self, steps: list, next_obs: np.ndarray, done: float) -> tuple:
        ret = sum(self.gamma ** k * reward for k, (_, _, reward) in enumerate(steps))
        return steps[0][0], steps[0][1], ret, next_obs, done, self.gamma ** len(steps)
