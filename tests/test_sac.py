"""SAC agents: network shapes, the squashed-Gaussian density, soft Bellman targets, PER weighting, temperature
tuning, target networks, determinism / checkpoints, and a small learning check."""
from __future__ import annotations

import copy
import dataclasses
import io
import math

import numpy as np
import pytest
import torch
from torch import nn
from torch.distributions import Independent, Normal, TransformedDistribution
from torch.distributions.transforms import TanhTransform

from policies.agents.action_scaler import ActionScaler
from policies.agents.discrete_sac import DiscreteSAC, DiscreteSacConfig
from policies.agents.networks import CategoricalActor, SquashedGaussianActor, TwinQ, TwinQDiscrete, mlp
from policies.agents.replay_batch import ReplayBatch
from policies.agents.sac import SAC, SacConfig
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


def linear_shapes(module: nn.Module) -> list[tuple[int, int]]:
    return [(m.in_features, m.out_features) for m in module.modules() if isinstance(m, nn.Linear)]


def count(module: nn.Module, kind: type) -> int:
    return sum(isinstance(m, kind) for m in module.modules())


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


def first_rows(batch: ReplayBatch, b: int) -> ReplayBatch:
    return ReplayBatch(**{name: value[:b] for name, value in batch.stored_fields().items()})


def weighted(batch: ReplayBatch, weights: np.ndarray) -> ReplayBatch:
    return dataclasses.replace(batch, weights=weights)


# ---------------------------------------------------------------------------------------------------- shapes
def test_paper_preset_network_shapes():
    cfg = TrainConfig.from_preset("paper")
    actor = SquashedGaussianActor(276, 4, cfg.actor, cfg.log_std_bounds)
    assert linear_shapes(actor.trunk) == [(276, 512), (512, 512), (512, 512), (512, 256)]
    assert linear_shapes(actor.mean) == [(256, 4)] and linear_shapes(actor.log_std) == [(256, 4)]
    assert count(actor, nn.LayerNorm) == 4 and count(actor, nn.Dropout) == 4 and count(actor, nn.ReLU) == 4

    critic = TwinQ(276, 4, cfg.critic)
    for q in (critic.q1, critic.q2):
        assert linear_shapes(q) == [(280, 512), (512, 512), (512, 256), (256, 1)]
        assert count(q, nn.LayerNorm) == 3 and count(q, nn.Dropout) == 3
    assert critic.q1[0].weight.data_ptr() != critic.q2[0].weight.data_ptr()  # independent, not shared

    meta_actor = CategoricalActor(272, 4, cfg.meta_actor)
    assert linear_shapes(meta_actor) == [(272, 256), (256, 256), (256, 4)]
    assert count(meta_actor, nn.LayerNorm) == 2 and count(meta_actor, nn.Dropout) == 2
    meta_critic = TwinQDiscrete(272, 4, cfg.meta_critic)
    assert linear_shapes(meta_critic.q1) == linear_shapes(meta_critic.q2) == [(276, 256), (256, 256), (256, 1)]
    assert all(isinstance(d, nn.Dropout) and d.p == 0.1 for d in meta_critic.modules() if isinstance(d, nn.Dropout))

    obs, act = torch.randn(5, 276), torch.rand(5, 4) * 2 - 1
    mean, log_std = actor(obs)
    assert mean.shape == log_std.shape == (5, 4)
    assert [t.shape for t in critic(obs, act)] == [(5,), (5,)]
    assert meta_actor(obs[:, :272]).shape == (5, 4)
    assert [t.shape for t in meta_critic(obs[:, :272], torch.tensor([0, 1, 2, 3, 0]))] == [(5,), (5,)]
    assert [t.shape for t in meta_critic.all_actions(obs[:, :272])] == [(5, 4), (5, 4)]


def test_default_preset_has_no_dropout_and_agents_build_from_presets():
    cfg = TrainConfig.from_preset("default")
    agent = SAC(276, 4, ENV_LOW, ENV_HIGH, as_sac(cfg))
    assert linear_shapes(agent.actor.trunk) == [(276, 256), (256, 256)]
    assert linear_shapes(agent.critic.q1) == [(280, 256), (256, 256), (256, 1)]
    meta = DiscreteSAC(272, 4, as_meta(cfg))
    assert linear_shapes(meta.actor) == [(272, 256), (256, 256), (256, 4)]
    assert linear_shapes(meta.critic.q1) == [(276, 256), (256, 256), (256, 1)]
    for module in (agent.actor, agent.critic, meta.actor, meta.critic):
        assert count(module, nn.Dropout) == 0 and count(module, nn.LayerNorm) > 0
    assert agent.target_entropy == -4.0 and agent.alpha == pytest.approx(0.2)
    assert meta.target_entropy == pytest.approx(0.89 * math.log(4))


@pytest.mark.filterwarnings("ignore:`torch.jit.script` is deprecated:DeprecationWarning")
def test_mlp_layer_order_and_scripting():
    net = mlp(6, NetworkConfig(hidden=(8,), head=5, layer_norm=True, dropout=0.2), 3)
    kinds = [type(m) for m in net]
    assert kinds == [nn.Linear, nn.LayerNorm, nn.ReLU, nn.Dropout] * 2 + [nn.Linear]
    assert isinstance(net, nn.Sequential)
    net.eval()
    x = torch.randn(4, 6)
    torch.testing.assert_close(torch.jit.script(net)(x), net(x))
    actor = SquashedGaussianActor(6, 2, NetworkConfig(hidden=(8,), dropout=0.1)).eval()
    exported = torch.export.export(actor, (x,))
    for got, want in zip(exported.module()(x), actor(x)):
        torch.testing.assert_close(got, want)


def test_twin_q_discrete_all_actions_matches_forward():
    torch.manual_seed(0)
    critic = TwinQDiscrete(5, 3, NetworkConfig(hidden=(16,)))
    obs = torch.randn(7, 5)
    q1_all, q2_all = critic.all_actions(obs)
    for a in range(3):
        q1, q2 = critic(obs, torch.full((7,), a))
        torch.testing.assert_close(q1_all[:, a], q1)
        torch.testing.assert_close(q2_all[:, a], q2)
        one_hot = torch.nn.functional.one_hot(torch.full((7,), a), 3).float()
        torch.testing.assert_close(critic(obs, one_hot)[0], q1)


# ---------------------------------------------------------------------------------------------------- actor
def test_log_std_is_clamped_to_bounds():
    actor = SquashedGaussianActor(3, 2, NetworkConfig(hidden=(8,)), (-20.0, 2.0))
    obs = torch.randn(4, 3)
    for bias, expected in ((100.0, 2.0), (-100.0, -20.0), (0.5, 0.5)):
        constant_output(nn.Sequential(actor.log_std), bias)
        _, log_std = actor(obs)
        assert torch.all(log_std == expected)


def test_sample_in_unit_box_and_log_prob_matches_tanh_gaussian():
    torch.manual_seed(1)
    actor = SquashedGaussianActor(5, 4, NetworkConfig(hidden=(32, 32)))
    obs = torch.randn(256, 5) * 3
    generator = torch.Generator().manual_seed(3)
    start = generator.get_state()
    action, log_prob = actor.sample(obs, generator)
    assert action.shape == (256, 4) and log_prob.shape == (256,)
    assert torch.all(action.abs() < 1.0)

    # The same pre-tanh sample, rebuilt from the same generator state, through torch.distributions.
    generator.set_state(start)
    mean, log_std = actor(obs)
    u = mean + log_std.exp() * torch.randn(mean.shape, generator=generator)
    tanh = TanhTransform(cache_size=1)
    squashed = tanh(u)
    reference = TransformedDistribution(Independent(Normal(mean, log_std.exp()), 1), [tanh])
    torch.testing.assert_close(squashed, action)
    torch.testing.assert_close(log_prob, reference.log_prob(squashed), atol=1e-4, rtol=1e-5)
    assert torch.all(torch.isfinite(log_prob))

    # Stable where tanh saturates: far-out means give finite log-densities.
    constant_output(nn.Sequential(actor.mean), 15.0)
    action, log_prob = actor.sample(obs, generator)
    assert torch.all(torch.isfinite(log_prob)) and torch.all(action <= 1.0)
    torch.testing.assert_close(actor.deterministic(obs), torch.tanh(actor(obs)[0]))


def test_action_scaler_round_trip_and_ranges():
    scaler = ActionScaler(ENV_LOW, ENV_HIGH)
    np.testing.assert_allclose(scaler.to_env(-np.ones(4)), ENV_LOW)
    np.testing.assert_allclose(scaler.to_env(np.ones(4)), ENV_HIGH)
    np.testing.assert_allclose(scaler.to_env(np.zeros(4)), [0.0, 0.0, 0.5, 0.5])
    unit = np.random.default_rng(0).uniform(-1, 1, (100, 4)).astype(np.float32)
    env = scaler.to_env(unit)
    assert np.all(env >= ENV_LOW) and np.all(env <= ENV_HIGH)
    np.testing.assert_allclose(scaler.to_unit(env), unit, atol=1e-6)
    t = torch.from_numpy(unit)
    assert isinstance(scaler.to_env(t), torch.Tensor)
    torch.testing.assert_close(scaler.to_env(t), torch.from_numpy(env))
    torch.testing.assert_close(scaler.to_unit(scaler.to_env(t)), t)
    with pytest.raises(ValueError):
        ActionScaler([0.0, 1.0], [1.0, 1.0])

    agent = SAC(6, 4, ENV_LOW, ENV_HIGH, as_sac(small_config()))
    actions = agent.act(np.random.default_rng(1).standard_normal((200, 6)).astype(np.float32) * 5)
    assert actions.shape == (200, 4) and actions.dtype == np.float32
    assert np.all(actions >= ENV_LOW) and np.all(actions <= ENV_HIGH)
    assert agent.act(np.zeros(6, np.float32)).shape == (4,)


# ---------------------------------------------------------------------------------------------------- targets
def test_action_margin_widens_the_policy_range_and_clips_to_the_environment():
    scaler = ActionScaler(ENV_LOW, ENV_HIGH, margin=0.25)  # movement [-1.5, 1.5], intensity / zoom [-0.25, 1.25]
    np.testing.assert_allclose(scaler.to_env(np.zeros(4)), [0.0, 0.0, 0.5, 0.5])  # the same centre
    np.testing.assert_allclose(scaler.to_env(np.full(4, 0.4)), [0.6, 0.6, 0.8, 0.8], rtol=1e-6)
    np.testing.assert_allclose(scaler.to_env(np.full(4, 2 / 3)), ENV_HIGH, rtol=1e-6)  # the bound short of tanh's 1
    np.testing.assert_allclose(scaler.to_env(np.full(4, 0.9)), ENV_HIGH)  # beyond: clipped
    np.testing.assert_allclose(scaler.to_env(-np.ones(4)), ENV_LOW)
    np.testing.assert_allclose(scaler.to_unit(ENV_HIGH), np.full(4, 2 / 3), rtol=1e-6)
    unit = torch.tensor([[0.9, -0.95, 0.3, -0.5]], requires_grad=True)
    flown = scaler.flown(unit)
    torch.testing.assert_close(flown, torch.tensor([[2 / 3, -2 / 3, 0.3, -0.5]]))
    flown.sum().backward()  # the critics' gradient reaches the policy only inside the environment's range
    torch.testing.assert_close(unit.grad, torch.tensor([[0.0, 0.0, 1.0, 1.0]]))
    plain = torch.tensor([[0.9, -0.95, 0.3, -0.5]])
    assert ActionScaler(ENV_LOW, ENV_HIGH).flown(plain) is plain  # no margin: the action as it is
    with pytest.raises(ValueError, match="action margin must be a finite number >= 0, got -0.1"):
        ActionScaler(ENV_LOW, ENV_HIGH, margin=-0.1)
    with pytest.raises(ValueError, match=r"TrainConfig.action_margin must be a number in \[0, 1\], got 1.5"):
        small_config(action_margin=1.5)


def test_critics_judge_the_flown_action_under_an_action_margin(monkeypatch):
    agent = SAC(3, 2, LOW2, HIGH2, as_sac(small_config(action_margin=0.25)))  # second dimension [0, 1] -> [-0.25, 1.25]
    seen = []
    for critic in (agent.critic, agent.critic_target):  # the update's passes (forward_with)
        forward = critic.forward_with
        monkeypatch.setattr(critic, "forward_with", lambda obs, action, *args, forward=forward, **kwargs: (
            seen.append(action.detach()), forward(obs, action, *args, **kwargs))[1])
    sampled = torch.tensor([[0.9, -0.95], [0.3, 0.5]])

    def fake_sample(obs, generator=None, weights=None):
        mean, log_std = agent.actor(obs)
        return sampled + 0.0 * mean, 0.0 * log_std.sum(-1)

    monkeypatch.setattr(agent.actor, "sample", fake_sample)
    batch = continuous_batch(np.random.default_rng(0), 2)
    agent.update(batch)
    expected = torch.tensor([[2 / 3, -2 / 3], [0.3, 0.5]])
    target_action, buffer_action, policy_action = seen  # soft target, the critics on the batch, the actor step
    torch.testing.assert_close(target_action, expected)
    torch.testing.assert_close(policy_action, expected)
    torch.testing.assert_close(buffer_action, agent.scaler.to_unit(torch.from_numpy(batch.action)))
    actions = agent.act(np.zeros((1, 3), np.float32), deterministic=True)
    assert np.all(actions >= LOW2) and np.all(actions <= HIGH2)


def test_continuous_soft_bellman_target_with_done_and_discount(monkeypatch):
    agent = SAC(3, 2, LOW2, HIGH2, as_sac(small_config(initial_alpha=0.5)))
    constant_output(agent.critic_target.q1, 4.0)
    constant_output(agent.critic_target.q2, 1.5)  # min Q' = 1.5
    constant_output(agent.critic.q1, 0.25)
    constant_output(agent.critic.q2, -0.75)

    def fake_sample(obs, generator=None, weights=None):  # log pi(a|s) = obs[:, 0]; differentiable for the actor step
        mean, log_std = agent.actor(obs)
        return torch.tanh(mean) * 0.0, obs[:, 0] + 0.0 * log_std.sum(-1)

    monkeypatch.setattr(agent.actor, "sample", fake_sample)
    batch = ReplayBatch(
        obs=np.zeros((4, 3), np.float32),
        action=np.array([[0.0, 0.5], [1.0, 1.0], [-1.0, 0.0], [0.2, 0.3]], np.float32),
        reward=np.array([1.0, -2.0, 0.5, 3.0], np.float32),
        next_obs=np.array([[-1.0, 0, 0], [2.0, 0, 0], [0.5, 0, 0], [-3.0, 0, 0]], np.float32),
        done=np.array([0.0, 0.0, 1.0, 0.0], np.float32),
        discount=np.array([0.99, 0.5, 0.9, 0.0], np.float32),
    )
    log_pi_next = batch.next_obs[:, 0].astype(np.float64)
    expected = batch.reward + batch.discount * (1 - batch.done) * (1.5 - 0.5 * log_pi_next)
    y = agent.soft_q_target(torch.from_numpy(batch.reward), torch.from_numpy(batch.next_obs),
                            torch.from_numpy(batch.done), torch.from_numpy(batch.discount), torch.tensor(0.5))
    np.testing.assert_allclose(y.numpy(), expected, rtol=1e-6)

    td, metrics = agent.update(batch)
    np.testing.assert_allclose(td, 0.5 * (np.abs(0.25 - expected) + np.abs(-0.75 - expected)), rtol=1e-6)
    np.testing.assert_allclose(metrics["critic_loss"],
                               np.mean((0.25 - expected) ** 2 + (-0.75 - expected) ** 2), rtol=1e-5)
    assert metrics["q_mean"] == pytest.approx(-0.25) and metrics["alpha"] == pytest.approx(0.5)

    # Without a discount the config's discount of this SAC is used (HRL-SAC's low level here: low_level_gamma).
    assert agent.gamma == agent.config.gamma == small_config().low_level_gamma == 0.95
    batch.discount = None
    constant_output(agent.critic.q1, 0.25)
    constant_output(agent.critic.q2, -0.75)
    constant_output(agent.critic_target.q1, 4.0)
    constant_output(agent.critic_target.q2, 1.5)
    alpha = agent.alpha
    expected = batch.reward + 0.95 * (1 - batch.done) * (1.5 - alpha * log_pi_next)
    td, _ = agent.update(batch)
    np.testing.assert_allclose(td, 0.5 * (np.abs(0.25 - expected) + np.abs(-0.75 - expected)), rtol=1e-5)


def test_discrete_soft_value_target_and_actor_loss_by_hand(monkeypatch):
    agent = DiscreteSAC(3, 3, as_meta(small_config(initial_alpha=0.3)))
    logits = np.array([0.5, -1.0, 2.0])
    constant_output(agent.actor.net, logits)  # the same policy in every state
    pi = np.exp(logits) / np.exp(logits).sum()
    log_pi = np.log(pi)

    q1_next = np.array([[1.0, 2.0, 3.0], [0.0, -1.0, 5.0]])
    q2_next = np.array([[2.0, 1.0, 3.5], [1.0, -2.0, 4.0]])
    monkeypatch.setattr(agent.critic_target, "all_actions",
                        lambda obs: (torch.tensor(q1_next, dtype=torch.float32),
                                     torch.tensor(q2_next, dtype=torch.float32)))
    q1_now = np.array([[0.5, 0.0, -1.0], [2.0, 2.0, 1.0]])
    q2_now = np.array([[0.0, 1.0, -2.0], [3.0, 1.5, 0.0]])
    monkeypatch.setattr(agent.critic, "all_actions",
                        lambda obs: (torch.tensor(q1_now, dtype=torch.float32),
                                     torch.tensor(q2_now, dtype=torch.float32)))
    constant_output(agent.critic.q1, 0.7)
    constant_output(agent.critic.q2, -0.2)

    alpha = 0.3
    v_next = (pi * (np.minimum(q1_next, q2_next) - alpha * log_pi)).sum(-1)
    np.testing.assert_allclose(v_next, [(pi * ([1, 1, 3] - alpha * log_pi)).sum(),
                                        (pi * ([0, -2, 4] - alpha * log_pi)).sum()])
    torch.testing.assert_close(agent.soft_value(torch.zeros(2, 3), torch.tensor(alpha)),
                               torch.tensor(v_next, dtype=torch.float32))

    batch = ReplayBatch(obs=np.zeros((2, 3), np.float32), action=np.array([2, 0]),
                        reward=np.array([1.0, -0.5], np.float32), next_obs=np.zeros((2, 3), np.float32),
                        done=np.array([0.0, 1.0], np.float32), discount=np.array([0.99 ** 30, 0.99 ** 7], np.float32))
    np.testing.assert_allclose(agent.probabilities(np.zeros((1, 3), np.float32))[0], pi, rtol=1e-5)
    y = batch.reward + batch.discount * (1 - batch.done) * v_next
    td, metrics = agent.update(batch)
    np.testing.assert_allclose(td, 0.5 * (np.abs(0.7 - y) + np.abs(-0.2 - y)), rtol=1e-5)
    actor_loss = np.mean((pi * (alpha * log_pi - np.minimum(q1_now, q2_now))).sum(-1))
    assert metrics["actor_loss"] == pytest.approx(actor_loss, rel=1e-5)
    assert metrics["entropy"] == pytest.approx(-(pi * log_pi).sum(), rel=1e-5)
    assert metrics["alpha"] == pytest.approx(alpha)


def test_per_weights_scale_the_critic_loss():
    rng = np.random.default_rng(4)
    b = 16
    # done = 1: y = r exactly, so the targets do not depend on how much policy noise a batch size draws.
    batch = continuous_batch(rng, 2 * b, done=1.0)
    half = first_rows(batch, b)
    cfg = small_config()
    full, first_half, halved, plain = (SAC(3, 2, LOW2, HIGH2, as_sac(cfg), seed=5) for _ in range(4))

    td_full, m_full = full.update(weighted(batch, np.r_[np.full(b, 2.0), np.zeros(b)].astype(np.float32)))
    td_half, m_half = first_half.update(half)
    assert m_full["critic_loss"] == pytest.approx(m_half["critic_loss"], rel=1e-6)
    np.testing.assert_allclose(td_full[:b], td_half, rtol=1e-6)
    for p_full, p_half in zip(full.critic.parameters(), first_half.critic.parameters()):  # same gradient
        torch.testing.assert_close(p_full, p_half, rtol=1e-4, atol=1e-6)

    _, m_halved = halved.update(weighted(batch, np.full(2 * b, 0.5, np.float32)))
    _, m_plain = plain.update(batch)
    assert m_halved["critic_loss"] == pytest.approx(0.5 * m_plain["critic_loss"], rel=1e-6)

    meta_full, meta_half = DiscreteSAC(3, 3, as_meta(cfg), seed=2), DiscreteSAC(3, 3, as_meta(cfg), seed=2)
    dbatch = discrete_batch(rng, 2 * b)
    _, m1 = meta_full.update(weighted(dbatch, np.r_[np.full(b, 2.0), np.zeros(b)].astype(np.float32)))
    _, m2 = meta_half.update(first_rows(dbatch, b))
    assert m1["critic_loss"] == pytest.approx(m2["critic_loss"], rel=1e-5)


# ---------------------------------------------------------------------------------------------------- temperature
@pytest.mark.parametrize("target_entropy, grows", [(50.0, True), (-50.0, False)])
def test_continuous_alpha_moves_toward_target_entropy(target_entropy, grows):
    agent = SAC(3, 2, LOW2, HIGH2, as_sac(small_config(target_entropy=target_entropy)))
    rng = np.random.default_rng(0)
    start = agent.alpha
    for _ in range(5):
        agent.update(continuous_batch(rng, 32))
    assert (agent.alpha > start) if grows else (agent.alpha < start)


@pytest.mark.parametrize("logits, grows", [([6.0, 0.0, 0.0], True), ([0.0, 0.0, 0.0], False)])
def test_discrete_alpha_moves_toward_target_entropy(logits, grows):
    agent = DiscreteSAC(3, 3, as_meta(small_config()))  # target 0.89 log 3: peaked policy below, uniform above
    constant_output(agent.actor.net, logits)
    rng = np.random.default_rng(0)
    start = agent.alpha
    for _ in range(3):
        agent.update(discrete_batch(rng, 32))
    assert (agent.alpha > start) if grows else (agent.alpha < start)


def test_meta_alpha_never_below_floor():
    # A uniform policy held fixed (actor learning rate 0): H = log 3 stays above the target 0.89 log 3, so
    # alpha keeps shrinking -- onto the floor, and no further.
    cfg = small_config(initial_alpha=1.5e-3, meta_min_alpha=1e-3, learning_rate=0.05)
    agent = DiscreteSAC(3, 3, as_meta(cfg))
    constant_output(agent.actor.net, [0.0, 0.0, 0.0])
    agent.actor_optim.param_groups[0]["lr"] = 0.0
    rng = np.random.default_rng(0)
    for _ in range(30):
        _, metrics = agent.update(discrete_batch(rng, 16))
        assert metrics["entropy"] == pytest.approx(math.log(3))
        assert agent.alpha >= 1e-3 and metrics["alpha"] >= 1e-3
    assert agent.alpha == pytest.approx(1e-3, rel=1e-6)
    assert DiscreteSAC(3, 3, as_meta(small_config(initial_alpha=1e-5, meta_min_alpha=1e-3))).alpha >= 1e-3


# ---------------------------------------------------------------------------------------------------- targets move
def test_target_critics_move_by_tau():
    rng = np.random.default_rng(2)
    for agent, batch in ((SAC(3, 2, LOW2, HIGH2, as_sac(small_config(tau=0.1))), continuous_batch(rng, 16)),
                         (DiscreteSAC(3, 3, as_meta(small_config(tau=0.1))), discrete_batch(rng, 16))):
        agent.update(batch)  # online and target differ from here on
        before = [p.clone() for p in agent.critic_target.parameters()]
        agent.update(batch)
        for old, online, new in zip(before, agent.critic.parameters(), agent.critic_target.parameters()):
            assert not torch.equal(old, new)
            torch.testing.assert_close(new, torch.lerp(old, online.detach(), 0.1), rtol=0, atol=0)
            torch.testing.assert_close(new, old + 0.1 * (online.detach() - old), rtol=0, atol=1e-6)
        assert all(not p.requires_grad for p in agent.critic_target.parameters())


# ---------------------------------------------------------------------------------------------------- determinism
def test_deterministic_act_is_repeatable_in_eval_mode_paper_preset():
    cfg = TrainConfig.from_preset("paper")
    agent = SAC(276, 4, ENV_LOW, ENV_HIGH, as_sac(cfg), seed=3)
    obs = np.random.default_rng(0).standard_normal((5, 276)).astype(np.float32)
    first, second = agent.act(obs, deterministic=True), agent.act(obs, deterministic=True)
    np.testing.assert_array_equal(first, second)
    assert agent.actor.training  # restored for the updates
    with torch.no_grad():  # sanity: in train mode dropout would make the two calls differ
        assert not torch.equal(agent.actor.deterministic(torch.from_numpy(obs)),
                               agent.actor.deterministic(torch.from_numpy(obs)))
    assert not np.array_equal(agent.act(obs), agent.act(obs))  # stochastic: fresh noise per call
    again = SAC(276, 4, ENV_LOW, ENV_HIGH, as_sac(cfg), seed=3)
    np.testing.assert_array_equal(again.act(obs, deterministic=True), first)

    meta = DiscreteSAC(272, 4, as_meta(cfg), seed=3)
    meta_obs = obs[:, :272]
    np.testing.assert_array_equal(meta.act(meta_obs, deterministic=True), meta.act(meta_obs, deterministic=True))
    np.testing.assert_array_equal(meta.probabilities(meta_obs), meta.probabilities(meta_obs))
    np.testing.assert_allclose(meta.probabilities(meta_obs).sum(-1), 1.0, rtol=1e-6)
    goals = meta.act(np.repeat(meta_obs[:1], 400, axis=0))
    assert goals.dtype == np.int64 and goals.shape == (400,) and set(goals.tolist()) <= {0, 1, 2, 3}
    assert meta.actor.training


def test_seeded_and_leaves_global_rng_alone():
    outer = torch.get_rng_state()
    cfg = small_config(dropout=0.1)
    a, b, c = (SAC(3, 2, LOW2, HIGH2, as_sac(cfg), seed=s) for s in (1, 1, 2))
    batch = continuous_batch(np.random.default_rng(0), 8)
    a.update(batch)
    a.act(batch.obs)
    DiscreteSAC(3, 3, as_meta(cfg), seed=1).update(discrete_batch(np.random.default_rng(0), 8))
    assert torch.equal(torch.get_rng_state(), outer)
    assert torch.equal(b.actor.mean.weight, SAC(3, 2, LOW2, HIGH2, as_sac(cfg), seed=1).actor.mean.weight)
    assert not torch.equal(b.actor.mean.weight, c.actor.mean.weight)


def _assert_same_agents(a, b):
    for name in ("actor", "critic", "critic_target"):
        for (key, pa), pb in zip(getattr(a, name).state_dict().items(), getattr(b, name).state_dict().values()):
            assert torch.equal(pa, pb), f"{name}.{key} differs"
    assert torch.equal(a.log_alpha, b.log_alpha)


@pytest.mark.parametrize("kind", ["sac", "discrete"])
def test_state_dict_round_trip_gives_bit_identical_next_update(kind):
    rng = np.random.default_rng(7)
    cfg = small_config(dropout=0.1)  # dropout: the restored agent must also draw the same masks
    if kind == "sac":
        def make(seed):
            return SAC(3, 2, LOW2, HIGH2, as_sac(cfg), seed=seed)
        batches = [continuous_batch(rng, 16) for _ in range(3)]
    else:
        def make(seed):
            return DiscreteSAC(3, 3, as_meta(cfg), seed=seed)
        batches = [discrete_batch(rng, 16) for _ in range(3)]
    original = make(0)
    original.update(batches[0])
    original.update(batches[1])
    buffer = io.BytesIO()
    torch.save(original.state_dict(), buffer)
    buffer.seek(0)
    restored = make(99)
    restored.load_state_dict(torch.load(buffer))
    _assert_same_agents(original, restored)

    td_a, metrics_a = original.update(weighted(batches[2], np.linspace(0.5, 1.0, 16).astype(np.float32)))
    td_b, metrics_b = restored.update(weighted(batches[2], np.linspace(0.5, 1.0, 16).astype(np.float32)))
    assert metrics_a == metrics_b
    np.testing.assert_array_equal(td_a, td_b)
    _assert_same_agents(original, restored)
    for opt in ("actor_optim", "critic_optim", "alpha_optim"):
        state_a, state_b = getattr(original, opt).state_dict()["state"], getattr(restored, opt).state_dict()["state"]
        for key in state_a:
            assert torch.equal(state_a[key]["exp_avg_sq"], state_b[key]["exp_avg_sq"])
    np.testing.assert_array_equal(original.act(batches[0].obs), restored.act(batches[0].obs))
    assert original.num_updates == restored.num_updates == 3

    snapshot = copy.deepcopy(original.state_dict())  # a deep copy is a snapshot; continuing does not change it
    original.update(batches[0])
    assert not torch.equal(snapshot["critic"]["q1.0.weight"], original.critic.q1[0].weight)


def test_batch_shapes_are_checked():
    agent = SAC(3, 2, LOW2, HIGH2, as_sac(small_config()))
    batch = continuous_batch(np.random.default_rng(0), 8)
    with pytest.raises(ValueError, match="reward"):
        agent.update(dataclasses.replace(batch, reward=batch.reward[:, None]))
    with pytest.raises(ValueError, match="weights"):
        agent.update(weighted(batch, np.ones((8, 1), np.float32)))
    meta = DiscreteSAC(3, 3, as_meta(small_config()))
    dbatch = discrete_batch(np.random.default_rng(0), 8)
    with pytest.raises(ValueError, match="discount"):
        meta.update(dataclasses.replace(dbatch, discount=None))
    with pytest.raises(ValueError, match="action"):
        meta.update(dataclasses.replace(dbatch, action=np.full(8, 3)))


# ---------------------------------------------------------------------------------------------------- learning
def test_sac_learns_a_one_step_bandit():
    """One fixed state, reward = -||a - a*||^2, done = 1: the deterministic action converges to a*."""
    a_star = np.array([0.4, 0.8], np.float32)  # env range, low = [-1, 0], high = [1, 1]
    net = NetworkConfig(hidden=(64, 64), layer_norm=True)
    cfg = TrainConfig(actor=net, critic=net, learning_rate=1e-3, initial_alpha=0.05)
    agent = SAC(3, 2, LOW2, HIGH2, as_sac(cfg), seed=0)
    rng = np.random.default_rng(0)
    state = np.tile(np.array([0.5, -1.0, 2.0], np.float32), (128, 1))
    for _ in range(1000):
        batch = continuous_batch(rng, 128, done=1.0)  # uniform random actions, as from the warm-up
        batch.obs = batch.next_obs = state
        batch.reward = -((batch.action - a_star) ** 2).sum(-1).astype(np.float32)
        agent.update(batch)
    action = agent.act(state[0], deterministic=True)
    assert np.abs(action - a_star).max() < 0.1, action
    assert agent.alpha < 0.05  # entropy above -|A| = -2 at the start: the temperature came down


def test_the_low_level_and_flat_sac_discount_by_their_own_gamma():
    low, high = np.array([-1.0, -1.0]), np.array([1.0, 1.0])
    assert SAC(3, 2, low, high, as_sac(small_config(algo="sac")), seed=0).gamma == 0.99
    hrl = small_config(algo="hrl-sac", low_level_gamma=0.9)
    assert SAC(3, 2, low, high, as_sac(hrl), seed=0).gamma == 0.9
    assert TrainConfig.from_preset("paper").sac_gamma == 0.99  # the paper's table
    with pytest.raises(ValueError, match="TrainConfig.low_level_gamma must be a number in"):
        TrainConfig(low_level_gamma=1.5)


# ---------------------------------------------------------------------------------------------------- precision
def test_bfloat16_updates_keep_float32_outputs_and_track_the_float32_update():
    """update_dtype="bfloat16": the hidden matrix products round to bfloat16, the Q-values and losses stay float32,
    weights stay float32, the step is close to the float32 one (not equal), and the bandit is still learned."""
    rng = np.random.default_rng(3)
    batch = continuous_batch(rng, 64)
    agents = {dtype: SAC(3, 2, LOW2, HIGH2, as_sac(small_config(update_dtype=dtype)), seed=0) for dtype in ("float32",
                                                                                                  "bfloat16")}
    results = {dtype: agent.update(batch) for dtype, agent in agents.items()}
    td32, td16 = results["float32"][0], results["bfloat16"][0]
    assert td16.dtype == np.float32
    assert not np.array_equal(td32, td16)  # bfloat16 really ran
    np.testing.assert_allclose(td16, td32, rtol=0.05, atol=0.02)
    for p32, p16 in zip(agents["float32"].critic.parameters(), agents["bfloat16"].critic.parameters()):
        assert p16.dtype == torch.float32
        assert (p16 - p32).abs().max() < 1e-3  # one Adam step of ~lr = 3e-4, in the same direction
    with torch.autocast("cpu", dtype=torch.bfloat16):  # outputs are float32 even inside autocast
        q1, _ = agents["bfloat16"].critic(torch.zeros(4, 3), torch.zeros(4, 2))
        mean, log_std = agents["bfloat16"].actor(torch.zeros(4, 3))
    assert q1.dtype == mean.dtype == log_std.dtype == torch.float32


def test_bfloat16_updates_are_reproducible_and_resume_bit_identically():
    rng = np.random.default_rng(5)
    batches = [continuous_batch(rng, 16) for _ in range(3)]
    cfg = small_config(update_dtype="bfloat16")
    a, b = SAC(3, 2, LOW2, HIGH2, as_sac(cfg), seed=1), SAC(3, 2, LOW2, HIGH2, as_sac(cfg), seed=1)
    for batch in batches[:2]:
        a.update(batch)
        b.update(batch)
    restored = SAC(3, 2, LOW2, HIGH2, as_sac(cfg), seed=2)
    restored.load_state_dict(copy.deepcopy(a.state_dict()))
    outcomes = [agent.update(batches[2]) for agent in (a, b, restored)]
    for td, metrics in outcomes[1:]:
        np.testing.assert_array_equal(td, outcomes[0][0])
        assert metrics == outcomes[0][1]


def test_update_dtype_is_validated():
    with pytest.raises(ValueError, match="TrainConfig.update_dtype must be 'float32' or 'bfloat16', got 'float16'"):
        TrainConfig(update_dtype="float16")


# ---------------------------------------------------------------------------------------------------- input mask
def test_low_level_input_mask_ignores_the_map_and_only_for_hrl_sac():
    from autonomy.observation import LAYOUT_V3, LAYOUT_V4

    belief = LAYOUT_V4.by_name["belief"].slice
    mask = TrainConfig().low_level_input_mask
    assert mask.shape == (288,) and mask[belief].sum() == 0 and mask.sum() == 288 - 256
    v0 = TrainConfig.from_preset("default", task="SarSearch-v0").low_level_input_mask  # v0's map is "coverage"
    assert v0.shape == (276,) and v0[LAYOUT_V3.by_name["coverage"].slice].sum() == 0 and v0.sum() == 276 - 256
    assert TrainConfig(algo="sac").low_level_input_mask is None  # flat SAC plans the search itself
    assert TrainConfig.from_preset("paper").low_level_input_mask is None  # the paper's low level sees all
    assert TrainConfig(low_level_ignores=()).low_level_input_mask is None
    # runs written before the field existed saw everything, and must load as they were trained
    legacy = TrainConfig().to_dict()
    del legacy["low_level_ignores"]
    assert TrainConfig.from_dict(legacy).low_level_input_mask is None


def test_runs_from_before_the_intensity_weighted_coverage_bonus_load_as_trained():
    legacy = TrainConfig().to_dict()
    del legacy["coverage_by_intensity"]
    assert not TrainConfig.from_dict(legacy).coverage_by_intensity  # whole cells, as they were trained
    assert TrainConfig.from_dict(TrainConfig(coverage_by_intensity=True).to_dict()).coverage_by_intensity


def test_unknown_ignored_field_is_refused_with_the_field_names():
    with pytest.raises(ValueError, match=r"low_level_ignores must be a list of SarSearch-v1 observation field names "
                                         r"\(agent_position, target_offset, .*goal\), got \('coverage',\)"):
        TrainConfig(low_level_ignores=("coverage",))  # SarSearch-v0's field, not v1's


def test_masked_inputs_change_no_output_and_get_no_gradient():
    keep = np.array([1, 0, 1, 0, 1, 1], dtype=np.float32)
    agent = SAC(6, 4, ENV_LOW, ENV_HIGH, as_sac(small_config()), seed=1, input_mask=keep)
    rng = np.random.default_rng(0)
    obs = rng.standard_normal((16, 6)).astype(np.float32)
    other = obs.copy()
    other[:, keep == 0] = rng.standard_normal((16, 2)) * 100  # only the masked features differ
    np.testing.assert_array_equal(agent.act(obs, deterministic=True), agent.act(other, deterministic=True))
    action = torch.rand(16, 4) * 2 - 1
    for a, b in zip(agent.critic(torch.from_numpy(obs), action), agent.critic(torch.from_numpy(other), action)):
        torch.testing.assert_close(a, b)
    # an update moves the first layers' weights of the kept inputs only
    before = [agent.actor.trunk[1].weight.detach().clone(), agent.critic.q1[1].weight.detach().clone()]
    batch = continuous_batch(rng, 32, obs_dim=6, low=ENV_LOW, high=ENV_HIGH)
    agent.update(batch)
    for layer, old in zip((agent.actor.trunk[1], agent.critic.q1[1]), before):
        moved = (layer.weight.detach() != old).any(dim=0)
        assert not moved[:6][keep == 0].any() and moved[:6][keep == 1].all()
        assert moved[6:].all()  # the critic's action inputs are always seen


def test_the_meta_controller_can_ignore_fields_and_only_known_ones():
    from autonomy.observation import LAYOUT_V4

    config = TrainConfig(meta_ignores=("belief",))
    mask = config.meta_input_mask
    assert mask.shape == (LAYOUT_V4.meta_dim,) and mask[LAYOUT_V4.by_name["belief"].slice].sum() == 0
    assert mask.sum() == LAYOUT_V4.meta_dim - 256 and TrainConfig().meta_input_mask is None
    meta = DiscreteSAC(LAYOUT_V4.meta_dim, 4, as_meta(config), seed=2, input_mask=mask)
    rng = np.random.default_rng(0)
    obs = rng.standard_normal((8, LAYOUT_V4.meta_dim)).astype(np.float32)
    other = obs.copy()
    other[:, mask == 0] = rng.standard_normal((8, 256)) * 100  # only the belief differs
    np.testing.assert_array_equal(meta.probabilities(obs), meta.probabilities(other))
    for a, b in zip(meta.critic.all_actions(torch.from_numpy(obs)), meta.critic.all_actions(torch.from_numpy(other))):
        torch.testing.assert_close(a, b)
    with pytest.raises(ValueError, match=r"meta_ignores must be a list of SarSearch-v1 meta observation field names "
                                         r"\(agent_position, .*altitude\), got \('goal',\)"):
        TrainConfig(meta_ignores=("goal",))
    legacy = TrainConfig().to_dict()
    del legacy["meta_ignores"]  # runs from before the field: the meta-controller saw everything
    assert TrainConfig.from_dict(legacy).meta_input_mask is None
