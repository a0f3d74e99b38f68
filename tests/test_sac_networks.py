"""SAC agents' networks: the presets' shapes, the MLP's layer order and scripting, the squashed-Gaussian actor (its
log-std bounds, its density against torch.distributions), the action scaler, and the input masks (fields the low
level and the meta-controller ignore)."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from sac_helpers import ENV_HIGH, ENV_LOW, as_meta, as_sac, constant_output, continuous_batch, small_config
from torch import nn
from torch.distributions import Independent, Normal, TransformedDistribution
from torch.distributions.transforms import TanhTransform

from policies.agents.action_scaler import ActionScaler
from policies.agents.discrete_sac import DiscreteSAC
from policies.agents.networks import CategoricalActor, SquashedGaussianActor, TwinQ, TwinQDiscrete, mlp
from policies.agents.sac import SAC
from policies.config import NetworkConfig, TrainConfig


def linear_shapes(module: nn.Module) -> list[tuple[int, int]]:
    return [(m.in_features, m.out_features) for m in module.modules() if isinstance(m, nn.Linear)]


def count(module: nn.Module, kind: type) -> int:
    return sum(isinstance(m, kind) for m in module.modules())


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
