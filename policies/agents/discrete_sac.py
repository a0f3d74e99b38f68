"""Discrete Soft Actor-Critic (Christodoulou 2019, "Soft Actor-Critic for Discrete Action Settings"): the HRL-SAC
meta-controller choosing one of 4 goals every K low-level steps.

With a discrete action set the expectations over the policy are exact sums, so no action is sampled in the
update (see :meth:`DiscreteSAC.update`)::

    V(s') = sum_a pi(a|s') [min_j Q'_j(s', a) - alpha log pi(a|s')]
    y     = r + discount * (1 - done) * V(s')         r = K-step discounted return, discount = meta_gamma^k
    critic loss = mean(w * ((Q1(s, a) - y)^2 + (Q2(s, a) - y)^2))
    actor loss  = mean_s sum_a pi(a|s) [alpha log pi(a|s) - min_j Q_j(s, a)]
    alpha loss  = mean_s log_alpha * (H(pi(.|s)) - target_entropy);  then log_alpha >= log(min_alpha)
    Q'_j <- Q'_j + tau * (Q_j - Q'_j)

The critics take the meta observation and the goal's one-hot and return a scalar; ``TwinQDiscrete.all_actions``
evaluates all goals in one batched pass. The target entropy is ``target_entropy_scale * log(n_actions)``
(entropies of a discrete policy are >= 0, unlike the continuous -|A|) and the temperature has a floor, two guards
against a meta-policy that collapses onto one goal. Dropout and eval mode follow the conventions of
:mod:`policies.agents.sac`; randomness, checkpoints and the rest the two agents share:
:mod:`policies.agents.off_policy`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from policies.agents.adam import adam_step, zero_grads
from policies.agents.networks import CategoricalActor, TwinQDiscrete
from policies.agents.off_policy import OffPolicyAgent, OffPolicyConfig
from policies.agents.replay_batch import ReplayBatch
from policies.config import TrainConfig


@dataclass(frozen=True)
class DiscreteSacConfig(OffPolicyConfig):
    """The settings of one discrete SAC: the actor maps the observation to one logit per action, each critic the
    observation and the action's one-hot to Q; an ``initial_alpha`` below ``min_alpha`` starts at the floor."""

    target_entropy_scale: float
    """The entropy target as a share of the largest entropy, log(n_actions): high enough that the policy keeps
    every action in use."""
    min_alpha: float
    """Floor on the temperature, a second guard against a policy that collapses onto one action."""

    @classmethod
    def from_train_config(cls, config: TrainConfig) -> DiscreteSacConfig:
        """HRL-SAC's meta-controller of a run (the ``meta_*`` settings)."""
        return cls(actor=config.meta_actor, critic=config.meta_critic, learning_rate=config.learning_rate,
                   tau=config.tau, initial_alpha=config.initial_alpha,
                   target_entropy_scale=config.meta_target_entropy_scale, min_alpha=config.meta_min_alpha)


class DiscreteSAC(OffPolicyAgent):
    """Discrete SAC with twin critics on (state, one-hot action), target critics and a floored temperature.

    Args:
        obs_dim: meta observation size (the task's layout: 284 on SarSearch-v1, 272 on SarSearch-v0).
        n_actions: number of goals (4).
        config: the settings (:class:`DiscreteSacConfig`).
        seed: the only source of randomness (network init, goal sampling, dropout masks).
        input_mask: (obs_dim,) 0 / 1, the observation features the networks see; None: all of them.
    """

    def __init__(self, obs_dim: int, n_actions: int, config: DiscreteSacConfig, seed: int = 0,
                 input_mask: np.ndarray | None = None):
        if n_actions < 2:
            raise ValueError(f"n_actions must be at least 2, got {n_actions}")
        self.n_actions = int(n_actions)
        self.target_entropy = float(config.target_entropy_scale * math.log(n_actions))
        self.min_alpha = float(config.min_alpha)
        self._min_log_alpha = math.log(self.min_alpha)
        super().__init__(obs_dim, config, seed, input_mask)

    def _build_networks(self, input_mask: np.ndarray | None) -> tuple[CategoricalActor, TwinQDiscrete]:
        cfg = self.config
        return (CategoricalActor(self.obs_dim, self.n_actions, cfg.actor, input_mask),
                TwinQDiscrete(self.obs_dim, self.n_actions, cfg.critic, input_mask))

    def _initial_log_alpha(self) -> float:
        return max(super()._initial_log_alpha(), self._min_log_alpha)

    # ------------------------------------------------------------------------------------------------ acting
    def _alpha(self) -> torch.Tensor:
        # log_alpha is clamped after every step; the clamp_min here also absorbs exp(log(floor)) rounding below
        # the floor in float32, so the alpha actually used is never below min_alpha.
        return self.log_alpha.detach().exp().clamp_min(self.min_alpha)

    @property
    def alpha(self) -> float:
        return float(self._alpha())

    @torch.no_grad()
    def _logits(self, obs: np.ndarray) -> tuple[torch.Tensor, bool]:
        obs_t, single = self._observations(obs)
        was_training = self.actor.training
        self.actor.eval()  # no dropout when acting
        try:
            return self.actor(obs_t), single
        finally:
            self.actor.train(was_training)

    def act(self, obs: np.ndarray, deterministic: bool = False) -> np.ndarray:
        """Meta observations (B, obs_dim) -> goal indices (B,) int64: argmax, or a sample from pi(.|s)."""
        logits, single = self._logits(obs)
        if deterministic:
            goals = logits.argmax(-1)
        else:
            goals = torch.multinomial(F.softmax(logits, -1), 1, generator=self.generator).squeeze(-1)
        goals = goals.numpy().astype(np.int64)
        return goals[0] if single else goals

    def probabilities(self, obs: np.ndarray) -> np.ndarray:
        """pi(.|s) (B, n_actions) float32, eval mode."""
        logits, single = self._logits(obs)
        probs = F.softmax(logits, -1).numpy()
        return probs[0] if single else probs

    # ------------------------------------------------------------------------------------------------ learning
    @torch.no_grad()
    def soft_value(self, next_obs: torch.Tensor, alpha: torch.Tensor) -> torch.Tensor:
        """V(s') = sum_a pi(a|s') [min_j Q'_j(s', a) - alpha log pi(a|s')], exact over the actions; (B,)."""
        log_pi = F.log_softmax(self.actor(next_obs), -1)
        q1_next, q2_next = self.critic_target.all_actions(next_obs)
        return (log_pi.exp() * (torch.min(q1_next, q2_next) - alpha * log_pi)).sum(-1)

    def update(self, batch: ReplayBatch) -> tuple[np.ndarray, dict[str, float]]:
        """One step of critics, actor and temperature, then the Polyak step of the target critics.

        ``batch``: ``action`` (B,) integer goals, ``reward`` the discounted extrinsic return of the k low-level steps
        the goal ran, ``done`` = terminated within those steps, ``discount`` = meta_gamma ** k (required: k varies
        when an episode ends inside a goal, and a wrong default would silently bias every target), ``weights``
        PER's or None for ones.

        Returns the TD errors (B,) float32 and the metrics (:meth:`OffPolicyAgent._finish_update`); ``alpha`` is the
        value used in this update, ``entropy`` the mean H(pi(.|s)).
        """
        obs, action, reward, next_obs, done, discount, w = self._tensors(batch)

        with self.dropout_rng:
            alpha = self._alpha()

            # --- critics
            with torch.no_grad():
                y = reward + discount * (1.0 - done) * self.soft_value(next_obs, alpha)
            q1, q2 = self.critic(obs, action)
            critic_loss = (w * ((q1 - y).square() + (q2 - y).square())).mean()
            zero_grads(self.critic_optim)
            critic_loss.backward()
            adam_step(self.critic_optim)

            # --- actor: the expectation over actions is a sum, so Q enters as a constant (no reparameterisation).
            log_pi = F.log_softmax(self.actor(obs), -1)
            pi = log_pi.exp()
            with torch.no_grad():
                q1_all, q2_all = self.critic.all_actions(obs)
                q_min = torch.min(q1_all, q2_all)
            actor_loss = (pi * (alpha * log_pi - q_min)).sum(-1).mean()
            zero_grads(self.actor_optim)
            actor_loss.backward()
            adam_step(self.actor_optim)

            # --- temperature: gradient H - target, so alpha grows when the entropy is below the target.
            entropy = -(pi.detach() * log_pi.detach()).sum(-1)
            alpha_loss = (self.log_alpha * (entropy - self.target_entropy)).mean()
            zero_grads(self.alpha_optim)
            alpha_loss.backward()
            self.alpha_optim.step()
            with torch.no_grad():
                self.log_alpha.clamp_(min=self._min_log_alpha)

        return self._finish_update(q1, q2, y, critic_loss, actor_loss, alpha, alpha_loss, entropy.mean())

    def _actions(self, action: np.ndarray, b: int) -> torch.Tensor:
        action = np.asarray(action)
        if action.shape != (b,) or not np.issubdtype(action.dtype, np.integer):
            raise ValueError(f"batch.action must be integer goals of shape ({b},), got {action.dtype} {action.shape}")
        if b and (action.min() < 0 or action.max() >= self.n_actions):
            raise ValueError(f"batch.action must be in [0, {self.n_actions}), got {action.min()}..{action.max()}")
        return torch.as_tensor(action.astype(np.int64, copy=False))

    def _default_discount(self, b: int) -> torch.Tensor:
        raise ValueError("batch.discount (meta_gamma ** k per transition) is required for the meta update")
