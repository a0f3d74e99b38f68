"""Networks of the SAC agents (continuous low level / flat SAC, discrete meta-controller) and shared helpers.

Every network is built from :func:`mlp` / :func:`hidden_layers`, i.e. plain ``nn.Sequential`` stacks of
``Linear -> LayerNorm -> ReLU -> Dropout`` so that they script with TorchScript and trace with ``torch.export``.
The algorithms (``policies.agents.sac``, ``policies.agents.discrete_sac``) own the optimisers, targets and losses.

The continuous SAC's update evaluates the same layers through :class:`UpdateWeights` (``forward_with``), which
hands each matrix product its weights in the update's precision: float32 as they are, or bfloat16 copies cast once
per parameter value. Those are the operations CPU autocast performed (the same kernels on the same dtypes, so the
same bits, checked by tests/test_update_precision.py), without autocast's per-call casts of every weight and its
dispatch.

Shapes in the paper preset (``TrainConfig.from_preset("paper")``) on the paper's observation, SarSearch-v0's (on
SarSearch-v1 the observation is 288 wide, the meta observation 284)::

    SquashedGaussianActor  276 -> 512 -> 512 -> 512 -> 256 -> mean (4), log_std (4)
    TwinQ (each of two)    280 -> 512 -> 512 -> 256 -> 1
    CategoricalActor       272 -> 256 -> 256 -> 4 logits
    TwinQDiscrete (each)   276 (272 + one-hot 4) -> 256 -> 256 -> 1

Note: the paper's table lists the actor's last hidden layer (512 -> 256) with ReLU only; here every hidden layer,
including the ``head``, is ``Linear -> LayerNorm -> ReLU -> Dropout`` (one rule for every network).
"""
from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from policies.config import NetworkConfig

LOG_2 = math.log(2.0)
LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)


# ---------------------------------------------------------------------------------------------------- MLPs
class InputMask(nn.Module):
    """Multiplies the inputs by a constant 0 / 1 vector: the network ignores the features marked 0.

    Zeroed inputs give their first-layer weights no gradient, so the network behaves as if those features were
    absent while keeping the input width (and the artifact's observation layout). A buffer, so that checkpoints
    and exported artifacts carry it.
    """

    def __init__(self, keep: np.ndarray):
        super().__init__()
        keep = np.asarray(keep, dtype=np.float32).reshape(-1)
        if not np.all((keep == 0.0) | (keep == 1.0)):
            raise ValueError("InputMask.keep must hold only 0 and 1")
        self.register_buffer("keep", torch.from_numpy(keep.copy()))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x * self.keep.to(x.dtype)


def hidden_layers(in_dim: int, net: NetworkConfig, input_mask: np.ndarray | None = None) -> list[nn.Module]:
    """The hidden part of an MLP: [InputMask] then, per width in ``net.layers``: Linear -> [LayerNorm] -> ReLU ->
    [Dropout]."""
    layers: list[nn.Module] = [] if input_mask is None else [InputMask(input_mask)]
    width = int(in_dim)
    for hidden in net.layers:
        layers.append(nn.Linear(width, hidden))
        if net.layer_norm:
            layers.append(nn.LayerNorm(hidden))
        layers.append(nn.ReLU())
        if net.dropout > 0:
            layers.append(nn.Dropout(net.dropout))
        width = hidden
    return layers


def mlp(in_dim: int, net: NetworkConfig, out_dim: int, input_mask: np.ndarray | None = None) -> nn.Sequential:
    """``hidden_layers(in_dim, net, input_mask)`` followed by a final ``Linear(net.layers[-1], out_dim)``."""
    return nn.Sequential(*hidden_layers(in_dim, net, input_mask), nn.Linear(net.layers[-1], int(out_dim)))


def float32_output(net: nn.Sequential, x: torch.Tensor) -> torch.Tensor:
    """``net(x)`` with the last layer (the output) in float32, also inside a bfloat16 autocast region.

    Under ``TrainConfig.update_dtype = "bfloat16"`` the hidden layers run their matrix products in bfloat16; the
    outputs (Q-values, action means) keep float32 precision because small differences between them are the
    whole learning signal (bfloat16 resolves Q = 50 only to 0.25). Outside autocast this is exactly ``net(x)``.
    """
    layers = list(net)
    for layer in layers[:-1]:
        x = layer(x)
    with torch.autocast("cpu", enabled=False):
        return layers[-1](x.float())


class UpdateWeights:
    """The parameters in the precision of an update's matrix products (``TrainConfig.update_dtype``).

    float32: the parameters themselves. bfloat16: a bfloat16 copy of each Linear weight and bias, cast at its first
    use and kept until :meth:`forget_casts` (after an optimiser step; fused Adam changes parameters without bumping
    their version counter) or until the parameter changes in place (a version bump: ``load_state_dict``, Polyak
    steps). One SAC update uses the actor's weights twice and the critics' weights of the actor step again in the
    next update's critic step, so caching saves those casts. A cast is made with autograd on, so that gradients
    reach the float32 parameter whichever pass (with or without grad) made it. The detached ("frozen") twin of
    each tensor is kept beside it: a frozen pass needs one per parameter, every update.
    """

    def __init__(self, dtype: torch.dtype):
        if dtype not in (torch.float32, torch.bfloat16):
            raise ValueError(f"UpdateWeights supports float32 and bfloat16, got {dtype}")
        self.dtype = dtype
        self._tensors: dict[tuple[int, torch.dtype], tuple[torch.Tensor, int, torch.Tensor, torch.Tensor]] = {}

    def __call__(self, param: torch.Tensor, frozen: bool = False) -> torch.Tensor:
        """``param`` in this precision (a Linear layer's weight or bias); ``frozen``: detached (no gradient)."""
        return self._get(param, self.dtype, frozen)

    def as_is(self, param: torch.Tensor, frozen: bool = False) -> torch.Tensor:
        """``param`` in its own dtype (LayerNorm's affine weights, the float32 output layers)."""
        return self._get(param, param.dtype, frozen)

    def _get(self, param: torch.Tensor, dtype: torch.dtype, frozen: bool) -> torch.Tensor:
        entry = self._tensors.get((id(param), dtype))
        # A cast is stale once its parameter changed; the parameter itself (and its detached view) never is.
        if entry is None or entry[0] is not param or (dtype != param.dtype and entry[1] != param._version):
            with torch.enable_grad():
                cast = param.to(dtype)  # the parameter itself when it already has the dtype
            entry = (param, param._version, cast, cast.detach())
            self._tensors[id(param), dtype] = entry
        return entry[3] if frozen else entry[2]

    def forget_casts(self, params) -> None:
        """Drop the casts of ``params`` (an optimiser step changed their values)."""
        for param in params:
            if param.dtype != self.dtype:
                self._tensors.pop((id(param), self.dtype), None)

    def forget(self, params) -> None:
        """Drop everything kept of ``params`` (their values, or the tensors themselves, were replaced)."""
        for param in params:
            self._tensors.pop((id(param), self.dtype), None)
            self._tensors.pop((id(param), param.dtype), None)

    def hidden(self, layers, x: torch.Tensor, frozen: bool = False) -> torch.Tensor:
        """``x`` through the hidden layers of an MLP (:func:`hidden_layers`: InputMask, Linear, LayerNorm, ReLU,
        Dropout), each Linear on this precision's weights and inputs. LayerNorm keeps its float32 affine weights
        on the low-precision activations, and Dropout follows its module's train / eval mode, as under autocast."""
        for layer in layers:
            if isinstance(layer, nn.Linear):
                x = F.linear(x.to(self.dtype), self(layer.weight, frozen), self(layer.bias, frozen))
            elif isinstance(layer, nn.LayerNorm):
                x = F.layer_norm(x, layer.normalized_shape, self.as_is(layer.weight, frozen),
                                 self.as_is(layer.bias, frozen), layer.eps)
            elif isinstance(layer, nn.ReLU):
                x = torch.relu(x)
            elif isinstance(layer, nn.Dropout):
                x = F.dropout(x, layer.p, layer.training)
            elif isinstance(layer, InputMask):
                x = layer(x)
            else:
                raise TypeError(f"UpdateWeights.hidden: unexpected layer {type(layer).__name__}")
        return x

    def output(self, layer: nn.Linear, x: torch.Tensor, frozen: bool = False) -> torch.Tensor:
        """An output layer in float32 on float32 inputs (as :func:`float32_output`)."""
        return F.linear(x, self.as_is(layer.weight, frozen), self.as_is(layer.bias, frozen))


class ActionGradientOnly(torch.autograd.Function):
    """The first Linear layers of frozen bfloat16 critics on ``cat(obs, act)``, with a backward to ``act`` only.

    The actor step needs dQ/da, not dQ/ds: autograd would compute the input gradient of the whole 280- or 292-wide
    first layer and keep 4 columns. Those columns, computed alone, are the same bits in bfloat16 (oneDNN's kernel
    does not depend on the other columns; checked by tests/test_update_precision.py against the full gradient), for
    about a fifth of an input-gradient product per critic. In float32 (MKL) they are not, so float32 keeps the full
    path.
    Forward: ``F.linear(cat(obs, act).to(bfloat16), W_i, b_i)`` per critic; backward: ``sum_i float(g_i @
    W_i[:, obs_dim:])``, the sum autograd forms where the critics' input gradients meet.
    """

    @staticmethod
    def forward(ctx, obs: torch.Tensor, act: torch.Tensor, *weights_and_biases: torch.Tensor):
        weights = weights_and_biases[0::2]
        ctx.save_for_backward(*weights)
        ctx.obs_dim = obs.shape[1]
        x = torch.cat([obs, act], dim=-1).to(torch.bfloat16)
        return tuple(F.linear(x, w, b) for w, b in zip(weights, weights_and_biases[1::2]))

    @staticmethod
    def backward(ctx, *grads: torch.Tensor):
        total = None
        for grad, weight in zip(grads, ctx.saved_tensors):
            part = (grad @ weight[:, ctx.obs_dim:]).float()
            total = part if total is None else total + part
        return (None, total) + (None,) * (2 * len(grads))


# ---------------------------------------------------------------------------------------------------- actors
class SquashedGaussianActor(nn.Module):
    """Gaussian policy squashed by tanh into [-1, 1]^act_dim (SAC, Haarnoja et al. 2018, appendix C).

    ``forward`` returns the pre-tanh mean and the clamped log standard deviation; ``sample`` draws a
    reparameterised action with its log-density; ``deterministic`` is ``tanh(mean)`` (evaluation / export).
    """

    def __init__(self, obs_dim: int, act_dim: int, net: NetworkConfig,
                 log_std_bounds: tuple[float, float] = (-20.0, 2.0), input_mask: np.ndarray | None = None):
        super().__init__()
        if not log_std_bounds[0] < log_std_bounds[1]:
            raise ValueError(f"log_std_bounds must be (low, high) with low < high, got {log_std_bounds}")
        self.obs_dim, self.act_dim = int(obs_dim), int(act_dim)
        self.trunk = nn.Sequential(*hidden_layers(obs_dim, net, input_mask))
        self.mean = nn.Linear(net.layers[-1], act_dim)
        self.log_std = nn.Linear(net.layers[-1], act_dim)
        self.log_std_min, self.log_std_max = float(log_std_bounds[0]), float(log_std_bounds[1])

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, obs_dim) -> pre-tanh mean (B, act_dim), log_std (B, act_dim) clamped to ``log_std_bounds``."""
        h = self.trunk(obs)
        with torch.autocast("cpu", enabled=False):  # the heads in float32 (see float32_output)
            h = h.float()
            # A hard clamp (as the paper's "clipped Gaussian"); the bounds are wide enough that it rarely binds.
            return self.mean(h), self.log_std(h).clamp(self.log_std_min, self.log_std_max)

    def forward_with(self, obs: torch.Tensor, weights: UpdateWeights) -> tuple[torch.Tensor, torch.Tensor]:
        """:meth:`forward` with the trunk's matrix products in ``weights``' precision (an update's pass)."""
        h = weights.hidden(self.trunk, obs).float()
        return weights.output(self.mean, h), weights.output(self.log_std, h).clamp(self.log_std_min, self.log_std_max)

    def sample(self, obs: torch.Tensor, generator: torch.Generator | None = None,
               weights: UpdateWeights | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Reparameterised sample: (action in [-1, 1] (B, act_dim), log pi(action | obs) (B,)); ``weights``: the
        update's precision (:meth:`forward_with`), None = :meth:`forward`.

        log pi(a) = log N(u; mean, std) - sum_i log(1 - tanh(u_i)^2) with u the pre-tanh sample, and
        log(1 - tanh(u)^2) = 2 (log 2 - u - softplus(-2u)) which stays finite where tanh(u) rounds to +-1.
        """
        mean, log_std = self(obs) if weights is None else self.forward_with(obs, weights)
        eps, u = self._noise(mean, log_std, generator)
        # Gaussian log-density written with eps, not (u - mean) / std: exact even when std ~ exp(-20).
        gaussian = (-0.5 * eps.square() - log_std - LOG_SQRT_2PI).sum(-1)
        squash = (2.0 * (LOG_2 - u - F.softplus(-2.0 * u))).sum(-1)
        return torch.tanh(u), gaussian - squash

    def sample_action(self, obs: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
        """``sample(obs, generator)[0]`` without the log-density (acting needs only the action)."""
        return torch.tanh(self._noise(*self(obs), generator)[1])

    @staticmethod
    def _noise(mean: torch.Tensor, log_std: torch.Tensor, generator: torch.Generator | None
               ) -> tuple[torch.Tensor, torch.Tensor]:
        """(eps, u = mean + std * eps) with eps ~ N(0, 1) drawn from ``generator``."""
        eps = torch.randn(mean.shape, generator=generator, dtype=mean.dtype, device=mean.device)
        return eps, mean + log_std.exp() * eps

    def deterministic(self, obs: torch.Tensor) -> torch.Tensor:
        """The mode-like action ``tanh(mean)`` in [-1, 1] (B, act_dim)."""
        mean, _ = self(obs)
        return torch.tanh(mean)


class CategoricalActor(nn.Module):
    """Discrete policy: obs (B, obs_dim) -> logits (B, n_actions) of a categorical distribution."""

    def __init__(self, obs_dim: int, n_actions: int, net: NetworkConfig, input_mask: np.ndarray | None = None):
        super().__init__()
        self.obs_dim, self.n_actions = int(obs_dim), int(n_actions)
        self.net = mlp(obs_dim, net, n_actions, input_mask)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.net(obs)


# ---------------------------------------------------------------------------------------------------- critics
class TwinQ(nn.Module):
    """Two independent Q-networks on concat(obs, action) (clipped double Q, Fujimoto et al. 2018)."""

    def __init__(self, obs_dim: int, act_dim: int, net: NetworkConfig, input_mask: np.ndarray | None = None):
        super().__init__()
        self.obs_dim, self.act_dim = int(obs_dim), int(act_dim)
        # input_mask covers the observation; the action is always seen
        mask = None if input_mask is None else np.concatenate([np.asarray(input_mask).reshape(-1), np.ones(act_dim)])
        self.q1 = mlp(obs_dim + act_dim, net, 1, mask)
        self.q2 = mlp(obs_dim + act_dim, net, 1, mask)

    def forward(self, obs: torch.Tensor, act: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, obs_dim), (B, act_dim) with act in the unit range [-1, 1] -> q1 (B,), q2 (B,)."""
        x = torch.cat([obs, act], dim=-1)
        return float32_output(self.q1, x).squeeze(-1), float32_output(self.q2, x).squeeze(-1)

    def forward_with(self, obs: torch.Tensor, act: torch.Tensor, weights: UpdateWeights, frozen: bool = False
                     ) -> tuple[torch.Tensor, torch.Tensor]:
        """:meth:`forward` with the hidden matrix products in ``weights``' precision (an update's pass).

        ``frozen``: no gradient to the critics' parameters (the actor step: the gradient flows to ``act`` only);
        in bfloat16 the first layers then skip the observation's part of the input gradient
        (:class:`ActionGradientOnly`)."""
        nets = (list(self.q1), list(self.q2))
        if frozen and weights.dtype == torch.bfloat16:
            # Both critics start with the same mask (if any), which keeps every action input (ones).
            first = 1 if isinstance(nets[0][0], InputMask) else 0
            x_obs = obs if first == 0 else nets[0][0](torch.cat([obs, act], dim=-1))[:, :self.obs_dim]
            layers = [weights(p, frozen=True) for net in nets for p in (net[first].weight, net[first].bias)]
            hidden = ActionGradientOnly.apply(x_obs, act, *layers)
            nets = tuple(net[first + 1:] for net in nets)
        else:
            x = torch.cat([obs, act], dim=-1)
            hidden = (x, x)
        q1, q2 = (weights.output(net[-1], weights.hidden(net[:-1], h, frozen).float(), frozen).squeeze(-1)
                  for net, h in zip(nets, hidden))
        return q1, q2


class TwinQDiscrete(nn.Module):
    """Twin Q(s, one_hot(a)) -> scalar for a discrete action set (the paper's meta critic: 272 + 4 inputs).

    ``forward`` evaluates the taken actions (B rows); ``all_actions`` evaluates every action of every state
    (B * n rows) for the soft value and the policy loss.
    """

    def __init__(self, obs_dim: int, n_actions: int, net: NetworkConfig, input_mask: np.ndarray | None = None):
        super().__init__()
        self.obs_dim, self.n_actions = int(obs_dim), int(n_actions)
        # input_mask covers the observation; the goal one-hot is always seen
        mask = None if input_mask is None else np.concatenate([np.asarray(input_mask).reshape(-1), np.ones(n_actions)])
        self.q1 = mlp(obs_dim + n_actions, net, 1, mask)
        self.q2 = mlp(obs_dim + n_actions, net, 1, mask)
        # Not persistent: a constant, it has no place in checkpoints.
        self.register_buffer("eye", torch.eye(n_actions), persistent=False)

    def forward(self, obs: torch.Tensor, action: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """obs (B, obs_dim), action (B,) integer indices or (B, n) one-hot -> q1 (B,), q2 (B,)."""
        one_hot = self.eye[action] if action.dim() == 1 else action.to(obs.dtype)
        x = torch.cat([obs, one_hot], dim=-1)
        return self.q1(x).squeeze(-1), self.q2(x).squeeze(-1)

    def all_actions(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """obs (B, obs_dim) -> q1 (B, n), q2 (B, n): every action of every state in one batched pass."""
        batch, n = obs.shape[0], self.n_actions
        x = torch.cat([obs.unsqueeze(1).expand(batch, n, self.obs_dim),
                       self.eye.to(obs.dtype).unsqueeze(0).expand(batch, n, n)], dim=-1).reshape(batch * n, -1)
        return self.q1(x).view(batch, n), self.q2(x).view(batch, n)
