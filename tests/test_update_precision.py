"""The SAC update's precision machinery (``UpdateWeights``, ``forward_with``, ``ActionGradientOnly``) computes what
the update computed before it, under CPU autocast, bit for bit: the outputs digested by benchmarks/output_digests.py
(training runs in bfloat16) depend on it. The oracle below is that earlier update, written with autocast and the
networks' own ``forward``."""
from __future__ import annotations

import contextlib

import numpy as np
import pytest
import torch

from policies.agents.networks import ActionGradientOnly, UpdateWeights
from policies.agents.replay_batch import ReplayBatch
from policies.agents.sac import SAC, SacConfig
from policies.agents.shared import polyak_update
from policies.config import NetworkConfig, TrainConfig
from policies.env.core import ACTION_HIGH, ACTION_LOW

NET = NetworkConfig(hidden=(48, 40), head=24, dropout=0.1)  # every layer kind: LayerNorm, Dropout, the head


def autocast_update(agent: SAC, batch: ReplayBatch) -> tuple[np.ndarray, list[float]]:
    """The update as it was: the forward passes under ``torch.autocast`` in bfloat16 (or none in float32) through the
    networks' ``forward``, the critics frozen for the actor step by ``requires_grad_(False)``."""
    obs, action, reward, next_obs, done, discount, w = agent._tensors(batch)
    action = agent.scaler.to_unit(action)
    bf16 = agent.config.update_dtype == "bfloat16"
    precision = (lambda: torch.autocast("cpu", dtype=torch.bfloat16)) if bf16 else contextlib.nullcontext
    with agent.dropout_rng:
        alpha = agent.log_alpha.detach().exp()
        with precision():
            with torch.no_grad():
                next_action, next_log_prob = agent.actor.sample(next_obs, agent.generator)
                q1_next, q2_next = agent.critic_target(next_obs, agent.scaler.flown(next_action))
                y = reward + discount * (1.0 - done) * (torch.min(q1_next, q2_next) - alpha * next_log_prob)
            q1, q2 = agent.critic(obs, action)
        critic_loss = agent._critic_step(q1, q2, y, w)  # the losses and optimiser steps are the update's own
        with precision():
            new_action, log_prob = agent.actor.sample(obs, agent.generator)
            agent.critic.requires_grad_(False)
            q1_pi, q2_pi = agent.critic(obs, agent.scaler.flown(new_action))
            agent.critic.requires_grad_(True)
        actor_loss, alpha_loss = agent._actor_step(alpha, log_prob, q1_pi, q2_pi)
    polyak_update(list(agent.critic.parameters()), list(agent.critic_target.parameters()), agent.tau)
    td = 0.5 * ((q1.detach() - y).abs() + (q2.detach() - y).abs())
    return td.numpy(), [critic_loss.item(), actor_loss.item(), alpha_loss.item()]


@pytest.mark.parametrize("algo", ["sac", "hrl-sac"])  # hrl-sac: the low level's input mask
@pytest.mark.parametrize("dtype", ["bfloat16", "float32"])
def test_update_equals_the_autocast_update_bit_for_bit(dtype, algo):
    config = TrainConfig.from_preset("default", algo=algo, update_dtype=dtype, actor=NET, critic=NET, batch_size=32,
                                     action_margin=0.25)
    dim, mask = config.layout.dim, config.low_level_input_mask
    agents = [SAC(dim, 4, ACTION_LOW, ACTION_HIGH, SacConfig.from_train_config(config), seed=7, input_mask=mask)
              for _ in range(2)]
    rng = np.random.default_rng(0)
    for _ in range(6):
        batch = ReplayBatch(obs=rng.standard_normal((32, dim)).astype(np.float32),
                            action=rng.uniform(ACTION_LOW, ACTION_HIGH, (32, 4)).astype(np.float32),
                            reward=rng.standard_normal(32).astype(np.float32),
                            next_obs=rng.standard_normal((32, dim)).astype(np.float32),
                            done=(rng.random(32) < 0.2).astype(np.float32))
        batch.weights = rng.uniform(0.5, 1.0, 32).astype(np.float32)
        td, metrics = agents[0].update(batch)
        td_oracle, losses = autocast_update(agents[1], batch)
        np.testing.assert_array_equal(td, td_oracle)
        assert [metrics["critic_loss"], metrics["actor_loss"], metrics["alpha_loss"]] == losses
        np.testing.assert_array_equal(agents[0].act(batch.obs[:3]), agents[1].act(batch.obs[:3]))
    for name in ("actor", "critic", "critic_target"):
        for (key, a), b in zip(getattr(agents[0], name).state_dict().items(),
                               getattr(agents[1], name).state_dict().values()):
            assert torch.equal(a, b), f"{name}.{key}"


@pytest.mark.parametrize("width", [280, 292])  # the flat SAC and the low level's critic inputs (obs + 4 actions)
def test_action_gradient_only_gives_the_action_columns_of_the_full_gradient(width):
    generator = torch.Generator().manual_seed(1)
    obs, act = torch.randn(128, width - 4, generator=generator), torch.randn(128, 4, generator=generator)
    layers = [(torch.randn(256, width, generator=generator) * 0.05).bfloat16() for _ in range(2)]
    biases = [torch.randn(256, generator=generator).bfloat16() for _ in range(2)]
    grads = [torch.randn(128, 256, generator=generator).bfloat16() for _ in range(2)]

    full_act = act.clone().requires_grad_()
    x = torch.cat([obs, full_act], dim=-1)
    outputs = [torch.nn.functional.linear(x.to(torch.bfloat16), w, b) for w, b in zip(layers, biases)]
    torch.autograd.backward(outputs, grads)

    only_act = act.clone().requires_grad_()
    hidden = ActionGradientOnly.apply(obs, only_act, layers[0], biases[0], layers[1], biases[1])
    torch.autograd.backward(hidden, grads)
    for got, want in zip(hidden, outputs):
        assert torch.equal(got, want)
    assert torch.equal(only_act.grad, full_act.grad)


def test_update_weights_recast_after_a_change_and_pass_gradients_to_float32():
    layer = torch.nn.Linear(3, 2)
    weights = UpdateWeights(torch.bfloat16)
    first = weights(layer.weight)
    assert first.dtype == torch.bfloat16 and weights(layer.weight) is first  # cast once per value
    with torch.no_grad():
        layer.weight.add_(1.0)  # an in-place change (a version bump) is seen
    assert torch.equal(weights(layer.weight), layer.weight.detach().bfloat16())
    cast = weights(layer.weight)
    weights.forget_casts([layer.weight])  # fused Adam changes values without a version bump: the update says so
    assert weights(layer.weight) is not cast
    as_is = weights.as_is(layer.weight, frozen=True)
    assert as_is.dtype == torch.float32 and as_is.grad_fn is None and as_is.data_ptr() == layer.weight.data_ptr()
    with torch.no_grad():  # a cast made without grad still carries the gradient in a later pass with grad
        weights.forget([layer.weight])
        weights(layer.weight)
    weights(layer.weight).float().sum().backward()
    assert layer.weight.grad is not None and layer.weight.grad.dtype == torch.float32
    assert weights(layer.weight, frozen=True).grad_fn is None
    assert UpdateWeights(torch.float32)(layer.weight) is layer.weight


def test_acting_draws_the_action_that_sample_draws():
    config = SacConfig.from_train_config(TrainConfig.from_preset("default", actor=NET, critic=NET))
    agent = SAC(5, 4, ACTION_LOW, ACTION_HIGH, config, seed=2)
    obs = torch.randn(3, 5)
    state = agent.generator.get_state()
    with torch.no_grad():
        agent.actor.eval()
        sampled = agent.actor.sample(obs, agent.generator)[0]
        agent.generator.set_state(state)
        assert torch.equal(agent.actor.sample_action(obs, agent.generator), sampled)
