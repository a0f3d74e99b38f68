"""What the two SAC agents share (:class:`OffPolicyAgent`), so that each algorithm's module holds only the algorithm.

Both agents (``policies.agents.sac.SAC``, ``policies.agents.discrete_sac.DiscreteSAC``) are built the same way: an
actor and twin critics initialised from the agent's seed, target critics that start as copies of the critics,
a learned temperature alpha (optimised as log alpha), fused Adam for the networks and Adam for log alpha. They
check their inputs the same way, end every update with the Polyak step of the target critics, report the same
metrics and save the same checkpoint state. What differs (the networks, the action's type, the losses) is in
the subclasses.

Randomness: network initialisation, the policy's sampling (``self.generator``) and the dropout masks (a private
global-RNG stream, :class:`policies.agents.shared.PrivateTorchRNG`) come from three streams derived from ``seed``;
the caller's global torch RNG is neither used nor changed. All three are in ``state_dict``, so a resumed run
gives bit-identical next updates.
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np
import torch

from policies.agents.adam import fused_adam
from policies.agents.replay_batch import ReplayBatch
from policies.agents.shared import PrivateTorchRNG, as_float_tensor, derive_seeds, polyak_update
from policies.config import NetworkConfig

METRIC_NAMES = ("critic_loss", "actor_loss", "alpha", "alpha_loss", "entropy", "q_mean")
"""The metrics every ``update`` returns, in this order."""


@dataclass(frozen=True)
class OffPolicyConfig:
    """The settings every agent here has; each agent's config adds its own. Built from a run's ``TrainConfig``
    (``from_train_config``), which holds their defaults and checks their ranges."""

    actor: NetworkConfig
    """The actor's hidden layers."""
    critic: NetworkConfig
    """Each of the twin critics' hidden layers."""
    learning_rate: float
    """Adam's learning rate of the actor, the critics and the temperature."""
    tau: float
    """Polyak rate of the target critics."""
    initial_alpha: float
    """The temperature before the first update."""


class OffPolicyAgent:
    """An actor, twin critics with target copies, a learned temperature, their optimisers and random streams.

    A subclass sets what :meth:`_build_networks` needs before calling ``__init__``, builds its networks there,
    and implements ``act`` and ``update``.
    """

    _MODULES = ("actor", "critic", "critic_target", "actor_optim", "critic_optim", "alpha_optim")
    """The parts with a ``state_dict`` of their own, in checkpoint order."""

    def __init__(self, obs_dim: int, config: OffPolicyConfig, seed: int, input_mask: np.ndarray | None):
        self.config = config
        self.obs_dim = int(obs_dim)
        self.tau = float(config.tau)
        init_seed, sample_seed, dropout_seed = derive_seeds(seed, 3)
        with torch.random.fork_rng(devices=[]):  # initialise from our seed, leave the global RNG as it was
            torch.manual_seed(init_seed)
            self.actor, self.critic = self._build_networks(input_mask)
        self.critic_target = copy.deepcopy(self.critic).eval().requires_grad_(False)
        # Optimise log(alpha): keeps alpha positive and makes Adam's steps relative.
        self.log_alpha = torch.tensor(self._initial_log_alpha(), dtype=torch.float32, requires_grad=True)

        lr = config.learning_rate
        self.actor_optim = fused_adam(self.actor.parameters(), lr)  # stepped by policies.agents.adam.adam_step
        self.critic_optim = fused_adam(self.critic.parameters(), lr)
        self.alpha_optim = torch.optim.Adam([self.log_alpha], lr=lr)

        self.generator = torch.Generator().manual_seed(sample_seed)  # the policy's sampling in act and update
        self.dropout_rng = PrivateTorchRNG(dropout_seed)  # dropout masks during updates
        self.num_updates = 0
        self._critic_params = list(self.critic.parameters())
        self._target_params = list(self.critic_target.parameters())

    def _build_networks(self, input_mask: np.ndarray | None) -> tuple[torch.nn.Module, torch.nn.Module]:
        """(actor, critic), built with the agent's initialisation seed in force."""
        raise NotImplementedError

    def _initial_log_alpha(self) -> float:
        return math.log(self.config.initial_alpha)

    # ------------------------------------------------------------------------------------------------ inputs
    def _observations(self, obs: np.ndarray) -> tuple[torch.Tensor, bool]:
        """Observations (B, obs_dim), or one (obs_dim,), as a (B, obs_dim) float32 tensor; and whether it was one."""
        obs_t = torch.as_tensor(np.asarray(obs, dtype=np.float32))
        single = obs_t.dim() == 1
        if single:
            obs_t = obs_t.unsqueeze(0)
        if obs_t.dim() != 2 or obs_t.shape[1] != self.obs_dim:
            raise ValueError(f"obs must have shape (B, {self.obs_dim}) or ({self.obs_dim},), got {tuple(obs_t.shape)}")
        return obs_t, single

    def _tensors(self, batch: ReplayBatch):
        """The batch as tensors (obs, action, reward, next_obs, done, discount, weights), every shape checked."""
        obs = torch.as_tensor(np.asarray(batch.obs, dtype=np.float32))
        if obs.dim() != 2 or obs.shape[1] != self.obs_dim:
            raise ValueError(f"batch.obs must have shape (B, {self.obs_dim}), got {tuple(obs.shape)}")
        b = obs.shape[0]
        action = self._actions(batch.action, b)
        reward = as_float_tensor("reward", batch.reward, (b,))
        next_obs = as_float_tensor("next_obs", batch.next_obs, (b, self.obs_dim))
        done = as_float_tensor("done", batch.done, (b,))
        discount = (self._default_discount(b) if batch.discount is None
                    else as_float_tensor("discount", batch.discount, (b,)))
        w = torch.ones(b) if batch.weights is None else as_float_tensor("weights", batch.weights, (b,))
        return obs, action, reward, next_obs, done, discount, w

    def _actions(self, action: np.ndarray, b: int) -> torch.Tensor:
        """The batch's actions as the critics take them (shape checked)."""
        raise NotImplementedError

    def _default_discount(self, b: int) -> torch.Tensor:
        """The discount of transitions that carry none."""
        raise NotImplementedError

    # ------------------------------------------------------------------------------------------------ results
    def _finish_update(self, q1: torch.Tensor, q2: torch.Tensor, y: torch.Tensor, critic_loss: torch.Tensor,
                       actor_loss: torch.Tensor, alpha: torch.Tensor, alpha_loss: torch.Tensor, entropy: torch.Tensor
                       ) -> tuple[np.ndarray, dict[str, float]]:
        """The Polyak step of the target critics, then what ``update`` returns: the TD errors (B,), 0.5 (|Q1(s,a) - y|
        + |Q2(s,a) - y|) before the step (both critics are trained on y, so both count: the new PER priorities),
        and the metrics of :data:`METRIC_NAMES` (q_mean: the mean of Q1 and Q2 on the batch)."""
        polyak_update(self._critic_params, self._target_params, self.tau)
        self._targets_moved()
        self.num_updates += 1
        with torch.no_grad():
            td_errors = 0.5 * ((q1.detach() - y).abs() + (q2.detach() - y).abs())
            values = torch.stack([critic_loss.detach(), actor_loss.detach(), alpha, alpha_loss.detach(), entropy,
                                  0.5 * (q1.detach().mean() + q2.detach().mean())])
        return td_errors.numpy(), dict(zip(METRIC_NAMES, values.tolist()))  # one conversion for all metrics

    def _targets_moved(self) -> None:
        """Called after each Polyak step of the target critics (for caches of their weights)."""

    # ------------------------------------------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict:
        """Everything a resumed run needs: networks, target critics, optimisers, the temperature and every random
        stream (like ``nn.Module.state_dict``, tensors are shared: ``torch.save`` or deep-copy it for a snapshot)."""
        state = {name: getattr(self, name).state_dict() for name in self._MODULES}
        state.update(log_alpha=self.log_alpha.detach().clone(), generator=self.generator.get_state(),
                     dropout_rng=self.dropout_rng.state.clone(), num_updates=self.num_updates)
        return state

    def load_state_dict(self, state: dict) -> None:
        for name in self._MODULES:
            getattr(self, name).load_state_dict(state[name])
        with torch.no_grad():
            self.log_alpha.copy_(state["log_alpha"])  # in place: alpha_optim holds this very tensor
        self.generator.set_state(state["generator"])
        self.dropout_rng.state = state["dropout_rng"].clone()
        self.num_updates = int(state["num_updates"])
