"""Discrete Soft Actor-Critic (Christodoulou 2019, "Soft Actor-Critic for Discrete Action Settings"): the HRL-SAC
meta-controller choosing one of 4 goals every K low-level steps.

With a discrete action set the expectations over the policy are exact sums, so no action is sampled in the
update (see :meth:`DiscreteSAC.update`)::

    V(s') = sum_a pi(a|s') [min_j Q'_j(s', a) - alpha log pi(a|s')]
    y     = r + discount * (1 - done) * V(s')         r = K-step discounted return, discount = meta_gamma^k
    critic loss = mean(w * ((Q1(s, a) - y)^2 + (Q2(s, a) - y)^2))
    actor loss  = mean_s sum_a pi(a|s) [alpha log pi(a|s) - min_j Q_j(s, a)]
    alpha loss  = mean_s log_alpha * (H(pi(.|s)) - target_entropy);  then log_alpha >= log(meta_min_alpha)
    Q'_j <- Q'_j + tau * (Q_j - Q'_j)

The critics take the state and the goal's one-hot (the paper's 272 + 4 = 276 inputs) and return a scalar;
``TwinQDiscrete.all_actions`` evaluates all goals in one batched pass. The target entropy is
``meta_target_entropy_scale * log(n_actions)`` (entropies of a discrete policy are >= 0, unlike the
continuous -|A|) and the temperature has a floor, two guards against a meta-policy that collapses onto one goal.
Randomness, dropout, eval mode and checkpoints follow the same conventions as :mod:`policies.agents.sac`.
"""
from __future__ import annotations

import copy
import math

import numpy as np
import torch
import torch.nn.functional as F

from policies.config import TrainConfig
from policies.agents.adam import adam_step, fused_adam, zero_grads
from policies.agents.networks import CategoricalActor, TwinQDiscrete
from policies.agents.shared import CheckpointedAgent, PrivateTorchRNG, as_float_tensor, derive_seeds, polyak_update

METRIC_NAMES = ("critic_loss", "actor_loss", "alpha", "alpha_loss", "entropy", "q_mean")


class DiscreteSAC(CheckpointedAgent):
    """Discrete SAC with twin critics on (state, one-hot action), target critics and a floored temperature.

    Args:
        obs_dim: meta observation size (272).
        n_actions: number of goals (4).
        config: ``meta_actor`` / ``meta_critic`` networks, ``learning_rate``, ``tau``, ``initial_alpha``,
            ``meta_target_entropy_scale`` and ``meta_min_alpha`` are used.
        seed: the only source of randomness (network init, goal sampling, dropout masks).
    """

    def __init__(self, obs_dim: int, n_actions: int, config: TrainConfig, seed: int = 0,
                 input_mask: np.ndarray | None = None):
        if n_actions < 2:
            raise ValueError(f"n_actions must be at least 2, got {n_actions}")
        self.config = config
        self.obs_dim, self.n_actions = int(obs_dim), int(n_actions)
        self.tau = float(config.tau)
        self.target_entropy = float(config.meta_target_entropy_scale * math.log(n_actions))
        self.min_alpha = float(config.meta_min_alpha)
        self._min_log_alpha = math.log(self.min_alpha)

        init_seed, sample_seed, dropout_seed = derive_seeds(seed, 3)
        with torch.random.fork_rng(devices=[]):  # initialise from our seed, leave the global RNG as it was
            torch.manual_seed(init_seed)
            self.actor = CategoricalActor(obs_dim, n_actions, config.meta_actor, input_mask)
            self.critic = TwinQDiscrete(obs_dim, n_actions, config.meta_critic, input_mask)
        self.critic_target = copy.deepcopy(self.critic).eval().requires_grad_(False)
        initial = max(math.log(config.initial_alpha), self._min_log_alpha)
        self.log_alpha = torch.tensor(initial, dtype=torch.float32, requires_grad=True)

        lr = config.learning_rate
        self.actor_optim = fused_adam(self.actor.parameters(), lr)  # stepped by adam_step, as in policies.agents.sac
        self.critic_optim = fused_adam(self.critic.parameters(), lr)
        self.alpha_optim = torch.optim.Adam([self.log_alpha], lr=lr)

        self.generator = torch.Generator().manual_seed(sample_seed)  # goal sampling in act()
        self.dropout_rng = PrivateTorchRNG(dropout_seed)
        self.num_updates = 0
        self._critic_params = list(self.critic.parameters())
        self._target_params = list(self.critic_target.parameters())

    # ------------------------------------------------------------------------------------------------ acting
    def _alpha(self) -> torch.Tensor:
        # log_alpha is clamped after every step; the clamp_min here also absorbs exp(log(floor)) rounding below
        # the floor in float32, so the alpha actually used is never below meta_min_alpha.
        return self.log_alpha.detach().exp().clamp_min(self.min_alpha)

    @property
    def alpha(self) -> float:
        return float(self._alpha())

    @torch.no_grad()
    def _logits(self, obs: np.ndarray) -> tuple[torch.Tensor, bool]:
        obs_t = torch.as_tensor(np.asarray(obs, dtype=np.float32))
        single = obs_t.dim() == 1
        if single:
            obs_t = obs_t.unsqueeze(0)
        if obs_t.dim() != 2 or obs_t.shape[1] != self.obs_dim:
            raise ValueError(f"obs must have shape (B, {self.obs_dim}) or ({self.obs_dim},), "
                             f"got {tuple(obs_t.shape)}")
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

    def update(self, batch: dict[str, np.ndarray], weights: np.ndarray | None = None
               ) -> tuple[np.ndarray, dict[str, float]]:
        """One step of critics, actor and temperature, then the Polyak step of the target critics.

        Args:
            batch: ``obs`` (B, obs_dim), ``action`` (B,) integer goals, ``reward`` (B,) = the discounted
                extrinsic return of the k low-level steps the goal ran, ``next_obs`` (B, obs_dim), ``done`` (B,)
                = terminated within those steps, ``discount`` (B,) = meta_gamma ** k (required: k varies when
                an episode ends inside a goal, and a wrong default would silently bias every target).
            weights: PER importance weights (B,); None = ones.

        Returns:
            td_errors (B,) float32 = 0.5 (|Q1(s,a) - y| + |Q2(s,a) - y|) before the step; metrics: critic_loss,
            actor_loss, alpha (used in this update), alpha_loss, entropy (mean H(pi(.|s))), q_mean.
        """
        obs, action, reward, next_obs, done, discount, w = self._tensors(batch, weights)

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

        polyak_update(self._critic_params, self._target_params, self.tau)
        self.num_updates += 1

        with torch.no_grad():
            td_errors = 0.5 * ((q1.detach() - y).abs() + (q2.detach() - y).abs())
            values = torch.stack([critic_loss.detach(), actor_loss.detach(), alpha, alpha_loss.detach(),
                                  entropy.mean(), 0.5 * (q1.detach().mean() + q2.detach().mean())])
        return td_errors.numpy(), dict(zip(METRIC_NAMES, values.tolist()))

    def _tensors(self, batch: dict[str, np.ndarray], weights: np.ndarray | None):
        obs = torch.as_tensor(np.asarray(batch["obs"], dtype=np.float32))
        if obs.dim() != 2 or obs.shape[1] != self.obs_dim:
            raise ValueError(f"batch['obs'] must have shape (B, {self.obs_dim}), got {tuple(obs.shape)}")
        b = obs.shape[0]
        action_np = np.asarray(batch["action"])
        if action_np.shape != (b,) or not np.issubdtype(action_np.dtype, np.integer):
            raise ValueError(f"batch['action'] must be integer goals of shape ({b},), "
                             f"got {action_np.dtype} {action_np.shape}")
        if b and (action_np.min() < 0 or action_np.max() >= self.n_actions):
            raise ValueError(f"batch['action'] must be in [0, {self.n_actions}), got {action_np.min()}.."
                             f"{action_np.max()}")
        action = torch.as_tensor(action_np.astype(np.int64, copy=False))
        reward = as_float_tensor("reward", batch["reward"], (b,))
        next_obs = as_float_tensor("next_obs", batch["next_obs"], (b, self.obs_dim))
        done = as_float_tensor("done", batch["done"], (b,))
        if batch.get("discount") is None:
            raise ValueError("batch['discount'] (meta_gamma ** k per transition) is required for the meta update")
        discount = as_float_tensor("discount", batch["discount"], (b,))
        w = torch.ones(b) if weights is None else as_float_tensor("weights", weights, (b,))
        return obs, action, reward, next_obs, done, discount, w

