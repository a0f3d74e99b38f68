"""Adam steps for the agents' updates without torch.optim's per-call bookkeeping.

``torch.optim.Adam.step`` spends about 100 us of Python per call on a CPU (hooks, profiler records, regrouping the
tensors by device and dtype, its state checks) around one ``torch._fused_adam_`` kernel. SAC takes two or three
steps per update, a few thousand updates a minute, so :func:`adam_step` calls that kernel directly on the
optimizer's own state: the same kernel on the same tensors, so the same bits as ``optimizer.step()``
(tests/test_adam.py), and the optimizer stays a plain ``torch.optim.Adam`` for checkpoints and schedules (its
``lr`` is read at every step).
"""
from __future__ import annotations

import torch

_PLAIN = {"amsgrad": False, "weight_decay": 0.0, "maximize": False, "capturable": False, "differentiable": False,
          "decoupled_weight_decay": False, "fused": True}
"""The options under which Adam is exactly ``_foreach_add_(steps, 1)`` then ``_fused_adam_`` (an option an older torch
does not have is at its default, the value here)."""


def fused_adam(params, lr: float) -> torch.optim.Adam:
    """An Adam optimizer for :func:`adam_step`: fused (one kernel for all of a network's tensors, without the
    temporaries of torch's per-tensor (CPU default) or foreach paths; it rounds differently from those)."""
    return torch.optim.Adam(params, lr=lr, fused=True)


def zero_grads(optimizer: torch.optim.Optimizer) -> None:
    """``optimizer.zero_grad(set_to_none=True)`` without its profiler record."""
    for group in optimizer.param_groups:
        for param in group["params"]:
            param.grad = None


def adam_step(optimizer: torch.optim.Adam) -> None:
    """``optimizer.step()`` for a fused Adam, bit for bit.

    The direct path needs a single parameter group with the plain options of :func:`fused_adam`, every parameter
    with a gradient and its state created; anything else (the first step creates the state) goes through
    ``optimizer.step()``.
    """
    groups = optimizer.param_groups
    group = groups[0]
    params = group["params"]
    state = optimizer.state
    if (len(groups) != 1 or len(state) != len(params) or any(group.get(k, v) != v for k, v in _PLAIN.items())
            or getattr(optimizer, "grad_scale", None) is not None or getattr(optimizer, "found_inf", None) is not None):
        optimizer.step()
        return
    grads, exp_avgs, exp_avg_sqs, steps = [], [], [], []
    for param in params:
        if param.grad is None:
            optimizer.step()  # torch skips parameters without a gradient: leave that to it
            return
        entry = state[param]
        grads.append(param.grad)
        exp_avgs.append(entry["exp_avg"])
        exp_avg_sqs.append(entry["exp_avg_sq"])
        steps.append(entry["step"])
    beta1, beta2 = group["betas"]
    torch._foreach_add_(steps, 1)
    torch._fused_adam_(params, grads, exp_avgs, exp_avg_sqs, [], steps, amsgrad=False, lr=group["lr"], beta1=beta1,
                       beta2=beta2, weight_decay=0.0, eps=group["eps"], maximize=False, grad_scale=None, found_inf=None)
