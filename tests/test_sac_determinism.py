"""SAC agents' determinism and checkpoints: repeatable deterministic actions, seeding that leaves the global RNG
alone, state-dict round trips giving bit-identical next updates, batch shape checks, bfloat16 updates (float32
outputs, reproducible, resumed bit for bit), each level's own discount, and a small learning check."""
from __future__ import annotations

import copy
import dataclasses
import io

import numpy as np
import pytest
import torch
from sac_helpers import (ENV_HIGH, ENV_LOW, HIGH2, LOW2, as_meta, as_sac, continuous_batch, discrete_batch,
                         small_config, weighted)

from policies.agents.discrete_sac import DiscreteSAC
from policies.agents.sac import SAC
from policies.config import NetworkConfig, TrainConfig


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
