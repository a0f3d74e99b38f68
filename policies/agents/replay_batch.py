"""A minibatch of transitions: what the replay buffers sample and n-step returns complete, and what the agents'
``update`` learns from."""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np


@dataclass
class ReplayBatch:
    """B transitions, one row each, as numpy arrays; the observations raw or normalised, as the caller keeps them."""

    obs: np.ndarray
    """(B, obs_dim) observations the actions were taken in."""
    action: np.ndarray
    """(B, act_dim) actions in the environment's range (continuous SAC), or (B,) integer goals (meta-controller)."""
    reward: np.ndarray
    """(B,) rewards: one step's, n steps' discounted sum (n-step returns), or a goal's K-step discounted return."""
    next_obs: np.ndarray
    """(B, obs_dim) the observations the transitions ended in (the real last one of an episode, not the reset)."""
    done: np.ndarray
    """(B,) 1 where the episode terminated within the transition, else 0; a truncation still bootstraps."""
    discount: np.ndarray | None = None
    """(B,) the bootstrap discount of each transition (gamma^n, meta_gamma^k); None: the agent's own gamma."""
    weights: np.ndarray | None = None
    """(B,) prioritised replay's importance weights; None: all ones."""
    indices: np.ndarray | None = None
    """(B,) the buffer rows the transitions were sampled from, for the new priorities; None: not sampled."""

    TRANSITION_FIELDS: ClassVar[tuple[str, ...]] = ("obs", "action", "reward", "next_obs", "done", "discount")
    """The fields a replay buffer stores (``discount`` only when the transitions carry their own)."""

    @classmethod
    def from_fields(cls, fields: dict[str, np.ndarray], weights: np.ndarray | None = None,
                    indices: np.ndarray | None = None) -> ReplayBatch:
        """A batch from a replay buffer's named fields (every transition field, ``discount`` optional)."""
        return cls(**{name: fields[name] for name in cls.TRANSITION_FIELDS if name in fields},
                   weights=weights, indices=indices)

    def stored_fields(self) -> dict[str, np.ndarray]:
        """The transition fields that are set, by name: what ``PrioritizedReplayBuffer.add`` takes."""
        return {name: getattr(self, name) for name in self.TRANSITION_FIELDS if getattr(self, name) is not None}
