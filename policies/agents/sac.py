"""Continuous Soft Actor-Critic (Haarnoja et al. 2018, "SAC: Off-Policy Maximum Entropy Deep RL with a Stochastic
Actor", and 2019, "SAC Algorithms and Applications"): the HRL-SAC low level and the flat SAC baseline.

One update, top to bottom (see :meth:`SAC.update`)::

    a' ~ pi(.|s')                                          (no grad)
    y  = r + discount * (1 - done) * (min_j Q'_j(s', a') - alpha * log pi(a'|s'))
    critic loss = mean(w * ((Q1(s, a) - y)^2 + (Q2(s, a) - y)^2))        w = PER importance weights
    a~ ~ pi(.|s) (reparameterised);  actor loss = mean(alpha * log pi(a~|s) - min_j Q_j(s, a~))
    alpha loss  = -mean(log_alpha * (log pi(a~|s) + target_entropy))
    Q'_j <- Q'_j + tau * (Q_j - Q'_j)

Conventions:
- Observations are already normalised float32 (the caller's running mean / std).
- Actions cross this API in the *environment* range [low, high]; inside, actor and critics work in [-1, 1].
- ``done`` is *termination* only: a time-limit truncation still bootstraps.
- Randomness (the policy's Gaussian noise is ``self.generator``), checkpoints and what else the meta-controller
  shares: :mod:`policies.agents.off_policy`.
- Dropout (paper preset) is active for the online networks during updates; ``act`` always runs the actor in
  eval mode (dropout is a regulariser, exploration comes from the Gaussian), and the target critics are
  permanently in eval mode (their job is a low-variance bootstrap target).
- Precision (``SacConfig.update_dtype``): the update's passes run through ``forward_with`` and one
  :class:`policies.agents.networks.UpdateWeights`, which holds the bfloat16 casts of the weights between their
  changes (the same arithmetic as CPU autocast, bit for bit, minus its per-call casts); acting is float32.
"""
from __future__ import annotations

import contextlib
from dataclasses import dataclass

import numpy as np
import torch

from policies.agents.action_scaler import ActionScaler
from policies.agents.adam import adam_step, zero_grads
from policies.agents.networks import SquashedGaussianActor, TwinQ, UpdateWeights
from policies.agents.off_policy import OffPolicyAgent, OffPolicyConfig
from policies.agents.replay_batch import ReplayBatch
from policies.agents.shared import as_float_tensor
from policies.config import TrainConfig


@dataclass(frozen=True)
class SacConfig(OffPolicyConfig):
    """The settings of one continuous SAC: the actor maps the observation to the mean and log standard deviation of
    each action, each critic the observation and the action to Q."""

    gamma: float
    """Discount of transitions that carry no discount of their own (one-step transitions)."""
    log_std_bounds: tuple[float, float]
    """Clip of the actor's log standard deviation (keeps the policy's spread finite and non-zero)."""
    target_entropy: float | None
    """The entropy the temperature steers the policy towards; None: -act_dim (Haarnoja et al.'s heuristic)."""
    action_margin: float
    """Widening of the actor's range beyond the environment's, as a share of each range on each side
    (:class:`policies.agents.action_scaler.ActionScaler`); 0: tanh maps exactly onto the range."""
    update_dtype: str
    """"float32" or "bfloat16": the precision of the hidden layers' matrix products in updates."""

    @classmethod
    def from_train_config(cls, config: TrainConfig) -> SacConfig:
        """The continuous SAC of a run: HRL-SAC's low level (discounted by ``low_level_gamma``) or the flat SAC."""
        return cls(actor=config.actor, critic=config.critic, learning_rate=config.learning_rate,
                   gamma=config.sac_gamma, tau=config.tau, log_std_bounds=config.log_std_bounds,
                   target_entropy=config.target_entropy, initial_alpha=config.initial_alpha,
                   action_margin=config.action_margin, update_dtype=config.update_dtype)


class SAC(OffPolicyAgent):
    """Continuous SAC with twin critics, target critics and automatic entropy tuning.

    Args:
        obs_dim: observation size (the task's observation layout: 288 on SarSearch-v1, 276 on SarSearch-v0).
        act_dim: action size (4).
        action_low, action_high: the environment's action box; ``act`` returns and ``update`` takes actions in it.
        config: the settings (:class:`SacConfig`).
        seed: the only source of randomness (see :mod:`policies.agents.off_policy`).
        input_mask: (obs_dim,) 0 / 1, the observation features the networks see; None: all of them.
    """

    def __init__(self, obs_dim: int, act_dim: int, action_low: np.ndarray, action_high: np.ndarray,
                 config: SacConfig, seed: int = 0, input_mask: np.ndarray | None = None):
        self.act_dim = int(act_dim)
        self.scaler = ActionScaler(action_low, action_high, config.action_margin)
        if self.scaler.dim != self.act_dim:
            raise ValueError(f"action bounds have {self.scaler.dim} dimensions, act_dim is {self.act_dim}")
        self.gamma = float(config.gamma)
        self.target_entropy = float(-act_dim if config.target_entropy is None else config.target_entropy)
        super().__init__(obs_dim, config, seed, input_mask)
        self._actor_params = list(self.actor.parameters())
        self._params = self._actor_params + self._critic_params + self._target_params
        self._weights = UpdateWeights(torch.bfloat16 if config.update_dtype == "bfloat16" else torch.float32)
        # Without Dropout the train / eval mode changes nothing (LayerNorm, ReLU and Linear ignore it) and the
        # global torch RNG is never drawn from, so the per-call mode switches and RNG swaps can be skipped.
        self._actor_has_dropout = any(isinstance(m, torch.nn.Dropout) for m in self.actor.modules())
        self._has_dropout = self._actor_has_dropout or any(isinstance(m, torch.nn.Dropout)
                                                           for m in self.critic.modules())

    def _build_networks(self, input_mask: np.ndarray | None) -> tuple[SquashedGaussianActor, TwinQ]:
        cfg = self.config
        return (SquashedGaussianActor(self.obs_dim, self.act_dim, cfg.actor, cfg.log_std_bounds, input_mask),
                TwinQ(self.obs_dim, self.act_dim, cfg.critic, input_mask))

    # ------------------------------------------------------------------------------------------------ acting
    @property
    def alpha(self) -> float:
        return float(self.log_alpha.detach().exp())

    @torch.no_grad()
    def act(self, obs: np.ndarray, deterministic: bool = False) -> np.ndarray:
        """Normalised float32 observations (B, obs_dim) -> actions in the environment range (B, act_dim).

        ``deterministic``: ``tanh(mean)``, otherwise a sample from ``self.generator``. The actor runs in eval
        mode either way (no dropout). A single observation (obs_dim,) gives a single action (act_dim,).
        """
        obs_t, single = self._observations(obs)
        if not self._actor_has_dropout:
            unit = self.actor.deterministic(obs_t) if deterministic else self.actor.sample_action(obs_t, self.generator)
        else:
            was_training = self.actor.training
            self.actor.eval()
            try:
                unit = (self.actor.deterministic(obs_t) if deterministic
                        else self.actor.sample_action(obs_t, self.generator))
            finally:
                self.actor.train(was_training)
        action = self.scaler.to_env(unit).numpy()
        return action[0] if single else action

    # ------------------------------------------------------------------------------------------------ learning
    @torch.no_grad()
    def soft_q_target(self, reward: torch.Tensor, next_obs: torch.Tensor, done: torch.Tensor,
                      discount: torch.Tensor, alpha: torch.Tensor) -> torch.Tensor:
        """y = r + discount (1 - done) (min_j Q'_j(s', a') - alpha log pi(a'|s')), a' ~ pi(.|s'); shape (B,)."""
        next_action, next_log_prob = self.actor.sample(next_obs, self.generator, self._weights)
        # (without grad here, so nothing reaches the target critics' parameters without freezing them)
        q1_next, q2_next = self.critic_target.forward_with(next_obs, self.scaler.flown(next_action), self._weights)
        soft_value = torch.min(q1_next, q2_next) - alpha * next_log_prob
        return reward + discount * (1.0 - done) * soft_value

    def update(self, batch: ReplayBatch) -> tuple[np.ndarray, dict[str, float]]:
        """One gradient step of critics, actor and temperature, then the Polyak step of the target critics.

        ``batch``: actions (B, act_dim) in the ENVIRONMENT range, ``done`` = terminated (not truncated), ``discount``
        per transition (gamma^n for n-step returns) or None for ``gamma``, ``weights`` PER's or None for ones.

        Returns the TD errors (B,) float32 and the metrics (:meth:`OffPolicyAgent._finish_update`); ``alpha`` is the
        value used in this update, ``entropy`` -mean log pi(a~|s), a sample estimate of the policy's entropy.
        """
        obs, action, reward, next_obs, done, discount, w = self._tensors(batch)
        action = self.scaler.to_unit(action)  # the critics live in the actor's [-1, 1] space

        with self.dropout_rng if self._has_dropout else contextlib.nullcontext():
            alpha = self.log_alpha.detach().exp()

            # --- critics: regress both Q-networks on the soft Bellman target.
            y = self.soft_q_target(reward, next_obs, done, discount, alpha)
            q1, q2 = self.critic.forward_with(obs, action, self._weights)
            critic_loss = self._critic_step(q1, q2, y, w)

            # --- actor: maximise min_j Q_j(s, a~) + alpha H through the reparameterised sample, against the
            # critics just updated. Their parameters are frozen for this pass so that backward skips their
            # weight gradients (about a third of the actor step's cost) -- the gradient still flows to a~.
            new_action, log_prob = self.actor.sample(obs, self.generator, self._weights)
            q1_pi, q2_pi = self.critic.forward_with(obs, self.scaler.flown(new_action), self._weights, frozen=True)
            actor_loss, alpha_loss = self._actor_step(alpha, log_prob, q1_pi, q2_pi)

        return self._finish_update(q1, q2, y, critic_loss, actor_loss, alpha, alpha_loss, -log_prob.detach().mean())

    def _critic_step(self, q1: torch.Tensor, q2: torch.Tensor, y: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
        """The critics' loss (PER-weighted squared errors of both against y) and their optimiser step."""
        critic_loss = (w * ((q1 - y).square() + (q2 - y).square())).mean()
        zero_grads(self.critic_optim)
        critic_loss.backward()
        adam_step(self.critic_optim)
        self._weights.forget_casts(self._critic_params)
        return critic_loss

    def _actor_step(self, alpha: torch.Tensor, log_prob: torch.Tensor, q1_pi: torch.Tensor, q2_pi: torch.Tensor
                    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The actor's and the temperature's losses and optimiser steps; returns (actor_loss, alpha_loss)."""
        actor_loss = (alpha * log_prob - torch.min(q1_pi, q2_pi)).mean()
        # temperature: d loss / d log_alpha = E[-log pi] - target = H - target, so alpha grows when the entropy is
        # below the target and shrinks when it is above.
        alpha_loss = -(self.log_alpha * (log_prob.detach() + self.target_entropy)).mean()
        # One backward pass for both: the two losses share no parameter (the actor loss sees alpha detached, the
        # alpha loss sees log pi detached), so each gets exactly the gradient of its own loss, bit for bit.
        zero_grads(self.actor_optim)
        zero_grads(self.alpha_optim)
        (actor_loss + alpha_loss).backward()
        adam_step(self.actor_optim)
        self.alpha_optim.step()
        self._weights.forget_casts(self._actor_params)
        return actor_loss, alpha_loss

    def _targets_moved(self) -> None:
        self._weights.forget_casts(self._target_params)

    def load_state_dict(self, state: dict) -> None:
        super().load_state_dict(state)
        self._weights.forget(self._params)  # new values: nothing kept of the old ones may survive

    def _actions(self, action: np.ndarray, b: int) -> torch.Tensor:
        return as_float_tensor("action", action, (b, self.act_dim))

    def _default_discount(self, b: int) -> torch.Tensor:
        return torch.full((b,), self.gamma)
