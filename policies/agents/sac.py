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
- Randomness: network initialisation, the policy's Gaussian noise (``self.generator``) and the dropout masks
  (a private global-RNG stream, :class:`policies.agents.shared.PrivateTorchRNG`) come from three streams derived
  from ``seed``; the caller's global torch RNG is neither used nor changed. All three are in ``state_dict``,
  so a resumed run gives bit-identical next updates.
- Dropout (paper preset) is active for the online networks during updates; ``act`` always runs the actor in
  eval mode (dropout is a regulariser, exploration comes from the Gaussian), and the target critics are
  permanently in eval mode (their job is a low-variance bootstrap target).
- Precision (``TrainConfig.update_dtype``): the update's passes run through ``forward_with`` and one
  :class:`policies.agents.networks.UpdateWeights`, which holds the bfloat16 casts of the weights between their
  changes (the same arithmetic as CPU autocast, bit for bit, minus its per-call casts); acting is float32.
"""
from __future__ import annotations

import contextlib
import copy
import math

import numpy as np
import torch

from policies.config import TrainConfig
from policies.agents.adam import adam_step, fused_adam, zero_grads
from policies.agents.action_scaler import ActionScaler
from policies.agents.networks import SquashedGaussianActor, TwinQ, UpdateWeights
from policies.agents.shared import CheckpointedAgent, PrivateTorchRNG, as_float_tensor, derive_seeds, polyak_update

METRIC_NAMES = ("critic_loss", "actor_loss", "alpha", "alpha_loss", "entropy", "q_mean")


class SAC(CheckpointedAgent):
    """Continuous SAC with twin critics, target critics and automatic entropy tuning.

    Args:
        obs_dim: observation size (276 for SarSearch).
        act_dim: action size (4).
        action_low, action_high: the environment's action box; ``act`` returns and ``update`` takes actions in it.
        config: ``actor`` / ``critic`` networks, ``learning_rate``, ``sac_gamma``, ``tau``, ``log_std_bounds``,
            ``target_entropy`` (None = -act_dim) and ``initial_alpha`` are used.
        seed: the only source of randomness (see the module docstring).
    """

    def __init__(self, obs_dim: int, act_dim: int, action_low: np.ndarray, action_high: np.ndarray,
                 config: TrainConfig, seed: int = 0, input_mask: np.ndarray | None = None):
        self.config = config
        self.obs_dim, self.act_dim = int(obs_dim), int(act_dim)
        self.scaler = ActionScaler(action_low, action_high, config.action_margin)
        if self.scaler.dim != self.act_dim:
            raise ValueError(f"action bounds have {self.scaler.dim} dimensions, act_dim is {self.act_dim}")
        self.gamma, self.tau = float(config.sac_gamma), float(config.tau)
        self.target_entropy = float(-act_dim if config.target_entropy is None else config.target_entropy)

        init_seed, noise_seed, dropout_seed = derive_seeds(seed, 3)
        with torch.random.fork_rng(devices=[]):  # initialise from our seed, leave the global RNG as it was
            torch.manual_seed(init_seed)
            self.actor = SquashedGaussianActor(obs_dim, act_dim, config.actor, config.log_std_bounds, input_mask)
            self.critic = TwinQ(obs_dim, act_dim, config.critic, input_mask)
        self.critic_target = copy.deepcopy(self.critic).eval().requires_grad_(False)
        # Optimise log(alpha): keeps alpha positive and makes Adam's steps relative.
        self.log_alpha = torch.tensor(math.log(config.initial_alpha), dtype=torch.float32, requires_grad=True)

        lr = config.learning_rate
        self.actor_optim = fused_adam(self.actor.parameters(), lr)  # stepped by adam_step
        self.critic_optim = fused_adam(self.critic.parameters(), lr)
        self.alpha_optim = torch.optim.Adam([self.log_alpha], lr=lr)

        self.generator = torch.Generator().manual_seed(noise_seed)  # the policy's Gaussian noise
        self.dropout_rng = PrivateTorchRNG(dropout_seed)  # dropout masks during updates
        self.num_updates = 0
        self._critic_params = list(self.critic.parameters())
        self._target_params = list(self.critic_target.parameters())
        self._actor_params = list(self.actor.parameters())
        self._params = self._actor_params + self._critic_params + self._target_params
        self._weights = UpdateWeights(torch.bfloat16 if config.update_dtype == "bfloat16" else torch.float32)
        # Without Dropout the train / eval mode changes nothing (LayerNorm, ReLU and Linear ignore it) and the
        # global torch RNG is never drawn from, so the per-call mode switches and RNG swaps can be skipped.
        self._actor_has_dropout = any(isinstance(m, torch.nn.Dropout) for m in self.actor.modules())
        self._has_dropout = self._actor_has_dropout or any(isinstance(m, torch.nn.Dropout)
                                                           for m in self.critic.modules())

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
        obs_t = torch.as_tensor(np.asarray(obs, dtype=np.float32))
        single = obs_t.dim() == 1
        if single:
            obs_t = obs_t.unsqueeze(0)
        if obs_t.dim() != 2 or obs_t.shape[1] != self.obs_dim:
            raise ValueError(f"obs must have shape (B, {self.obs_dim}) or ({self.obs_dim},), got {tuple(obs_t.shape)}")
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

    def update(self, batch: dict[str, np.ndarray], weights: np.ndarray | None = None
               ) -> tuple[np.ndarray, dict[str, float]]:
        """One gradient step of critics, actor and temperature, then the Polyak step of the target critics.

        Args:
            batch: ``obs`` (B, obs_dim), ``action`` (B, act_dim) in the ENVIRONMENT range, ``reward`` (B,),
                ``next_obs`` (B, obs_dim), ``done`` (B,) = terminated (not truncated), optional ``discount``
                (B,) replacing ``gamma`` per sample (e.g. gamma^n for n-step returns).
            weights: PER importance weights (B,); None = ones.

        Returns:
            td_errors (B,) float32: 0.5 (|Q1(s,a) - y| + |Q2(s,a) - y|) before the step, i.e. the mean absolute
            error of the two critics (both are trained on y, so both count) -- the new PER priorities.
            metrics: critic_loss, actor_loss, alpha (the value used in this update), alpha_loss, entropy
            (-mean log pi(a~|s), a sample estimate of the policy entropy), q_mean (mean of Q1 and Q2 on the batch).
        """
        obs, action, reward, next_obs, done, discount, w = self._tensors(batch, weights)
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

        polyak_update(self._critic_params, self._target_params, self.tau)
        self._weights.forget_casts(self._target_params)
        self.num_updates += 1

        with torch.no_grad():
            td_errors = 0.5 * ((q1.detach() - y).abs() + (q2.detach() - y).abs())
            values = torch.stack([critic_loss.detach(), actor_loss.detach(), alpha, alpha_loss.detach(),
                                  -log_prob.detach().mean(), 0.5 * (q1.detach().mean() + q2.detach().mean())])
        return td_errors.numpy(), dict(zip(METRIC_NAMES, values.tolist()))  # one conversion for all metrics

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

    def load_state_dict(self, state: dict) -> None:
        super().load_state_dict(state)
        self._weights.forget(self._params)  # new values: nothing kept of the old ones may survive

    def _tensors(self, batch: dict[str, np.ndarray], weights: np.ndarray | None):
        obs = torch.as_tensor(np.asarray(batch["obs"], dtype=np.float32))
        if obs.dim() != 2 or obs.shape[1] != self.obs_dim:
            raise ValueError(f"batch['obs'] must have shape (B, {self.obs_dim}), got {tuple(obs.shape)}")
        b = obs.shape[0]
        action = as_float_tensor("action", batch["action"], (b, self.act_dim))
        reward = as_float_tensor("reward", batch["reward"], (b,))
        next_obs = as_float_tensor("next_obs", batch["next_obs"], (b, self.obs_dim))
        done = as_float_tensor("done", batch["done"], (b,))
        discount = (as_float_tensor("discount", batch["discount"], (b,)) if batch.get("discount") is not None
                    else torch.full((b,), self.gamma))
        w = torch.ones(b) if weights is None else as_float_tensor("weights", weights, (b,))
        return obs, action, reward, next_obs, done, discount, w

