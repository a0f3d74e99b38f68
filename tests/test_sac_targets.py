"""SAC agents' updates: soft Bellman targets (continuous and discrete, by hand), the action margin the critics judge,
PER weighting of the critic loss, temperature tuning toward the target entropy (and the meta-controller's floor),
and target networks moving by tau."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from sac_helpers import (ENV_HIGH, ENV_LOW, HIGH2, LOW2, as_meta, as_sac, constant_output, continuous_batch,
                         discrete_batch, small_config, weighted)

from policies.agents.action_scaler import ActionScaler
from policies.agents.discrete_sac import DiscreteSAC
from policies.agents.replay_batch import ReplayBatch
from policies.agents.sac import SAC


def first_rows(batch: ReplayBatch, b: int) -> ReplayBatch:
    return ReplayBatch(**{name: value[:b] for name, value in batch.stored_fields().items()})


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
