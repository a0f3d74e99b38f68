"""policies.agents.adam: the direct fused Adam step is torch's ``optimizer.step()``, bit for bit."""
from __future__ import annotations

import torch

from policies.agents.adam import adam_step, fused_adam, zero_grads


def _network() -> torch.nn.Sequential:
    torch.manual_seed(3)
    return torch.nn.Sequential(torch.nn.Linear(7, 16), torch.nn.LayerNorm(16), torch.nn.ReLU(), torch.nn.Linear(16, 2))


def _loss(net: torch.nn.Module, x: torch.Tensor) -> torch.Tensor:
    return net(x).square().mean()


def test_adam_step_gives_the_bits_of_optimizer_step_including_a_changed_learning_rate():
    ours, theirs = _network(), _network()
    ours_optim, theirs_optim = fused_adam(ours.parameters(), 1e-2), fused_adam(theirs.parameters(), 1e-2)
    generator = torch.Generator().manual_seed(0)
    for step in range(6):
        if step == 3:  # a schedule (or a test) changing the learning rate between steps
            for optim in (ours_optim, theirs_optim):
                optim.param_groups[0]["lr"] = 3e-3
        x = torch.randn(32, 7, generator=generator)
        zero_grads(ours_optim)
        _loss(ours, x).backward()
        adam_step(ours_optim)
        theirs_optim.zero_grad(set_to_none=True)
        _loss(theirs, x).backward()
        theirs_optim.step()
        for a, b in zip(ours.parameters(), theirs.parameters()):
            assert torch.equal(a, b)
            assert a.grad is not None
    for a, b in zip(ours_optim.state.values(), theirs_optim.state.values()):
        assert all(torch.equal(a[key], b[key]) for key in ("step", "exp_avg", "exp_avg_sq"))
    assert float(ours_optim.state[next(ours.parameters())]["step"]) == 6.0


def test_a_parameter_without_a_gradient_is_left_to_torch_which_skips_it():
    nets = _network(), _network()
    optims = [fused_adam(net.parameters(), 1e-2) for net in nets]
    steps = (adam_step, torch.optim.Adam.step)
    for net, optim, step in zip(nets, optims, steps):
        generator = torch.Generator().manual_seed(1)
        for _ in range(2):  # the first step creates the state
            zero_grads(optim)
            _loss(net, torch.randn(4, 7, generator=generator)).backward()
            net[3].bias.grad = None
            step(optim)
    for a, b in zip(*(net.parameters() for net in nets)):
        assert torch.equal(a, b)
    assert float(optims[0].state[nets[0][0].weight]["step"]) == 2.0
    assert nets[0][3].bias not in optims[0].state  # never had a gradient: torch never stepped it


def test_zero_grads_sets_every_gradient_to_none():
    net = _network()
    optim = fused_adam(net.parameters(), 1e-2)
    _loss(net, torch.randn(4, 7)).backward()
    zero_grads(optim)
    assert all(p.grad is None for p in net.parameters())
