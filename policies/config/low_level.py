"""The settings of the continuous SAC (HRL-SAC's low level, or flat SAC) and of prioritised replay; fields of
``TrainConfig``, which checks them."""
from __future__ import annotations

from dataclasses import dataclass, field

from policies.config.network import NetworkConfig


@dataclass(frozen=True)
class SacSettings:
    """The continuous SAC: its networks, optimiser, discounts, replay sizes, entropy and action range, precision."""

    actor: NetworkConfig = field(default_factory=NetworkConfig)
    """Low-level (or flat) actor: observation -> hidden -> (mean, log_std) of the 4 actions."""
    critic: NetworkConfig = field(default_factory=NetworkConfig)
    """Low-level twin critics: observation and the 4 actions -> hidden -> 1."""
    learning_rate: float = 3e-4
    """Adam learning rate of every network and of the entropy temperatures (the paper's table)."""
    gamma: float = 0.99
    """Discount of flat SAC (the paper's 0.99)."""
    low_level_gamma: float = 0.95
    """Discount of HRL-SAC's goal-conditioned low level (the paper preset: 0.99). Re-grounded goals make its
    return an endless chain of +1 per step of progress, so with 0.99 the critic's values (~100) dwarf the effect
    of one action and the low level flies slowly; 0.95 keeps one action's effect visible (docs/training.md, "How
    the defaults were chosen")."""
    tau: float = 0.005
    """Polyak rate of the target critics."""
    batch_size: int = 128
    """Low-level minibatch."""
    buffer_size: int = 100_000
    """Low-level replay capacity in transitions (each holds two float32 observations; the buffer is kept in
    checkpoints)."""
    warmup_steps: int = 2_000
    """Environment steps with uniform random actions before learning starts."""
    updates_per_step: float = 0.5
    """Gradient updates of the low-level SAC per environment step (1/num_envs = one per vector step)."""
    log_std_bounds: tuple[float, float] = (-20.0, 2.0)
    """Clip of the actor's log standard deviation (the paper's [-20, 2])."""
    target_entropy: float | None = None
    """Low-level entropy target; None = -|A| = -4."""
    action_margin: float = 0.0
    """Widening of the continuous SAC's action range beyond the environment's, as a share of each range on each
    side; the environment's range clips it. 0 = tanh maps exactly onto the range (the paper). At 0.25 the
    policy reaches full speed, the sensor fully on or the widest zoom at tanh 0.67 instead of tanh's saturation,
    where the entropy term holds the mean away from the bound and the critic's gradient vanishes. The critics
    judge the clipped (flown) action. The exported artifact applies the same map and clip."""
    initial_alpha: float = 0.2
    """Initial entropy temperature of both levels."""
    low_level_ignores: tuple[str, ...] = ("belief",)
    """Observation fields (``autonomy.observation.OBSERVATION_FIELDS`` names) that HRL-SAC's low-level actor and
    critics ignore: their inputs are multiplied by 0 (``networks.InputMask``), so the input keeps its width. Where
    to search is the meta-controller's choice; a low level that sees the coverage map learns to dawdle over it
    instead of flying to its goal. Flat SAC ignores this field (it plans the search itself). The paper preset: ()
    (the low level sees everything). SarSearch-v0's map field is "coverage", v1's "belief"."""

    update_dtype: str = "float32"
    """Precision of the hidden layers' matrix products in low-level / flat SAC updates: "float32" (the default) or
    "bfloat16" (weights, Adam, outputs and losses stay float32, acting stays float32; faster on CPUs with AVX-512
    BF16 or AMX, slower without). bfloat16 is a speed option, not a free one: learning was less reliable with it
    (docs/training.md, "How the defaults were chosen"). The two round differently: each is reproducible on a given
    CPU, they are not bit-equal."""


@dataclass(frozen=True)
class ReplaySettings:
    """Prioritised replay (both levels)."""

    per_alpha: float = 0.6
    """How strongly priorities skew sampling (0 = uniform)."""
    per_beta_start: float = 0.4
    """Importance-weight exponent at the start, annealed linearly to 1 over the run (over the steps before the
    meta-only phase, ``meta_only_steps``; 1 during it)."""
    per_eps: float = 1e-6
    """Added to |TD error| so that no transition gets priority 0."""
