"""The deterministic policy of a checkpoint as one self-contained torch module, ready to script or export.

Everything the evaluation path (``CheckpointPolicy``) does between a raw observation and an action happens
inside, so that the artifact needs no Python around it: the frozen observation normalisation (float64, like
``RunningMeanStd.normalize``, then float32), the networks without Dropout (identity in evaluation; removed,
it cannot be switched back on by a ``.train()``), ``tanh`` squashing and the affine map to the action ranges.
The operations are the eager ones in the same order, which is what makes the export agree with the eager
policy to float32 rounding (tests/test_export_parity.py).

    PolicyModule.act(obs: Tensor[N, 288]) -> Tensor[N, 4]          ActionHead (or Int8ActionHead)
    PolicyModule.select_goal(obs: Tensor[N, 284]) -> Tensor[N]     GoalHead (HRL-SAC) or NoGoal (flat SAC: -1)

Precision (``PRECISIONS``): "float32" is the policy as trained, operation for operation. "int8" is an opt-in for
the latency of a large low-level actor at batch 1 (docs/export.md, "Precision"): its hidden Linear layers keep
their weights as int8 with one float scale per output (``Int8Linear``, a quarter of the float32 bytes) and run on
bfloat16 activations; the action head and the normalisation run in float32 and the meta-controller stays as
trained, so goals are the trained ones exactly and actions agree to ``policies.export.parity.TOLERANCES["int8"]``.
"""
from __future__ import annotations

import copy

import torch
from torch import Tensor, nn

from autonomy.observation import META_OBS_DIM, NO_GOAL, OBS_DIM, OBSERVATION_LAYOUT_VERSION
from policies.agents.action_scaler import ActionScaler
from policies.agents.networks import CategoricalActor, SquashedGaussianActor
from policies.agents.normalizer import RunningMeanStd
from policies.checkpoint import CheckpointPolicy

PRECISIONS = ("float32", "int8")


def check_batch(x: Tensor, width: int) -> None:
    """Refuse anything but a (N, width) batch: a wrong width would otherwise fail deep inside a matmul."""
    if x.dim() != 2 or x.shape[1] != width:
        raise ValueError("expected observations of shape (N, " + str(width) + ")")


def without_dropout(layers: nn.Sequential) -> nn.Sequential:
    """A copy of ``layers`` minus its Dropout modules."""
    return nn.Sequential(*(copy.deepcopy(m) for m in layers if not isinstance(m, nn.Dropout)))


class FrozenNormalizer(nn.Module):
    """``RunningMeanStd.normalize`` with the statistics of the first ``width`` features frozen as buffers."""

    def __init__(self, normalizer: RunningMeanStd, width: int):
        super().__init__()
        self.width = int(width)
        self.clip = float(normalizer.clip)
        self.register_buffer("mean", torch.from_numpy(normalizer.mean[:width].copy()))
        self.register_buffer("std", torch.from_numpy(normalizer.std()[:width].copy()))

    def forward(self, x: Tensor) -> Tensor:
        check_batch(x, self.width)
        standardised = (x.to(torch.float64) - self.mean) / self.std
        return standardised.clamp(-self.clip, self.clip).to(torch.float32)


class Float32Normalizer(nn.Module):
    """:class:`FrozenNormalizer` in float32, as ``(x - mean) * (1 / std)``: for the int8 head, whose activations are
    bfloat16 anyway, two operations fewer per call than the float64 path (the rounding differs in the last float32
    bits, far inside the int8 tolerance)."""

    def __init__(self, normalizer: RunningMeanStd, width: int):
        super().__init__()
        self.width = int(width)
        self.clip = float(normalizer.clip)
        self.register_buffer("mean", torch.from_numpy(normalizer.mean[:width].astype("float32")))
        self.register_buffer("inverse_std", torch.from_numpy((1.0 / normalizer.std()[:width]).astype("float32")))

    def forward(self, x: Tensor) -> Tensor:
        check_batch(x, self.width)
        return ((x - self.mean) * self.inverse_std).clamp(-self.clip, self.clip)


class ActionHead(nn.Module):
    """Raw observations (N, 288) -> deterministic actions (N, 4) in the environment's action ranges."""

    def __init__(self, normalizer: RunningMeanStd, actor: SquashedGaussianActor, scaler: ActionScaler):
        super().__init__()
        self.normalize = FrozenNormalizer(normalizer, actor.obs_dim)
        self.trunk = without_dropout(actor.trunk)
        self.mean = copy.deepcopy(actor.mean)  # the log-std head plays no part in the deterministic action
        self.register_buffer("policy_low", torch.from_numpy(scaler.policy_low.copy()))
        self.register_buffer("half_range", torch.from_numpy(scaler.half_range))
        self.register_buffer("low", torch.from_numpy(scaler.low.copy()))
        self.register_buffer("high", torch.from_numpy(scaler.high.copy()))

    def forward(self, obs: Tensor) -> Tensor:
        unit = torch.tanh(self.mean(self.trunk(self.normalize(obs))))  # SquashedGaussianActor.deterministic
        return self.to_action_range(unit)

    def to_action_range(self, unit: Tensor) -> Tensor:
        """``ActionScaler.to_env``: the unit box onto the (margin-widened) action box, clipped to the actions'."""
        return torch.clamp(self.policy_low + (unit + 1.0) * self.half_range, self.low, self.high)


class Int8Linear(nn.Module):
    """A Linear layer whose weight is int8 with one scale per output row (symmetric, round to nearest), applied to
    bfloat16 inputs by ``torch._weight_int8pack_mm`` (the weight-only int8 kernel made for small batches).

    At batch 1 a policy step reads every weight once, so its time follows the weights' bytes: a quarter of
    float32's. The rounding error of a weight is at most half its row's scale (max |w| / 254).
    """

    def __init__(self, linear: nn.Linear):
        super().__init__()
        weight = linear.weight.detach().float()
        scale = weight.abs().amax(dim=1).clamp_min(torch.finfo(torch.float32).tiny) / 127.0
        self.register_buffer("weight", torch.round(weight / scale[:, None]).clamp(-127, 127).to(torch.int8))
        self.register_buffer("scale", scale.to(torch.bfloat16))
        self.register_buffer("bias", linear.bias.detach().to(torch.bfloat16))

    def forward(self, x: Tensor) -> Tensor:
        return torch._weight_int8pack_mm(x, self.weight, self.scale) + self.bias


def int8_layers(layers: nn.Sequential) -> nn.Sequential:
    """``layers`` (already without Dropout) with every Linear as an :class:`Int8Linear`; LayerNorm and ReLU as they
    are (LayerNorm takes the bfloat16 activations with its float32 weights)."""
    return nn.Sequential(*(Int8Linear(m) if isinstance(m, nn.Linear) else m for m in layers))


class Int8ActionHead(ActionHead):
    """:class:`ActionHead` with its hidden layers in int8 weights and bfloat16 activations (precision "int8"); the
    normalisation (:class:`Float32Normalizer`), the mean head and the map to the action ranges are float32."""

    def __init__(self, normalizer: RunningMeanStd, actor: SquashedGaussianActor, scaler: ActionScaler):
        super().__init__(normalizer, actor, scaler)
        self.normalize = Float32Normalizer(normalizer, actor.obs_dim)
        self.trunk = int8_layers(self.trunk)
        # to_action_range as one multiply-add: low' + (u + 1) * half = (low' + half) + u * half
        self.register_buffer("unit_zero", self.policy_low + self.half_range)

    def forward(self, obs: Tensor) -> Tensor:
        unit = torch.tanh(self.mean(self.trunk(self.normalize(obs).to(torch.bfloat16)).float()))
        return torch.clamp(torch.addcmul(self.unit_zero, unit, self.half_range), self.low, self.high)


class GoalHead(nn.Module):
    """Raw meta observations (N, 284) -> the most probable goal (N,) int64."""

    def __init__(self, normalizer: RunningMeanStd, actor: CategoricalActor):
        super().__init__()
        self.normalize = FrozenNormalizer(normalizer, actor.obs_dim)
        self.net = without_dropout(actor.net)

    def forward(self, meta_obs: Tensor) -> Tensor:
        return self.net(self.normalize(meta_obs)).argmax(-1)


class NoGoal(nn.Module):
    """Flat SAC has no meta-controller: every row gets NO_GOAL (-1), the all-zero goal one-hot it trained with."""

    def __init__(self):
        super().__init__()
        self.width, self.no_goal = META_OBS_DIM, NO_GOAL  # attributes: TorchScript does not read globals

    def forward(self, meta_obs: Tensor) -> Tensor:
        check_batch(meta_obs, self.width)
        return torch.full((meta_obs.shape[0],), self.no_goal, dtype=torch.int64)


class PolicyModule(nn.Module):
    """The two entry points of a policy artifact (``forward`` is ``act``, the call made every step)."""

    def __init__(self, action_head: nn.Module, goal_head: GoalHead | NoGoal):
        """``action_head``: an :class:`ActionHead` (or its int8 form), or ``policies.export.sb3.SB3ActionHead``."""
        super().__init__()
        self.action_head = action_head
        self.goal_head = goal_head

    @torch.jit.export
    def act(self, obs: Tensor) -> Tensor:
        """Raw observations (N, 288) -> actions (N, 4) in their ranges."""
        return self.action_head(obs)

    @torch.jit.export
    def select_goal(self, obs: Tensor) -> Tensor:
        """Raw meta observations (N, 284) -> goal indices (N,) int64; -1 for flat SAC."""
        return self.goal_head(obs)

    def forward(self, obs: Tensor) -> Tensor:
        return self.act(obs)


def policy_module(policy: CheckpointPolicy, precision: str = "float32") -> PolicyModule:
    """The exportable module of a checkpoint policy (copies: later training does not change it) in ``precision``
    (one of ``PRECISIONS``)."""
    if precision not in PRECISIONS:
        raise ValueError(f"unknown precision {precision!r} (choose {' or '.join(PRECISIONS)})")
    layout = policy.config.layout
    if layout.version != OBSERVATION_LAYOUT_VERSION:
        raise ValueError(f"the policy was trained on {policy.config.task} (observation layout {layout.version}); "
                         f"the runtime flies layout {OBSERVATION_LAYOUT_VERSION} ({OBS_DIM} values): train on "
                         "SarSearch-v1 to export")
    if policy.low.obs_dim != OBS_DIM:
        raise ValueError(f"the low-level actor takes {policy.low.obs_dim} values, the observation has {OBS_DIM}")
    head = Int8ActionHead if precision == "int8" else ActionHead
    action_head = head(policy.normalizer, policy.low.actor, policy.low.scaler)
    goal_head = GoalHead(policy.normalizer, policy.meta.actor) if policy.meta is not None else NoGoal()
    return PolicyModule(action_head, goal_head).eval().requires_grad_(False)
