"""The settings of HRL-SAC's meta-controller (the discrete SAC choosing the goals, its replay and its meta-only
phase); fields of ``TrainConfig``, which checks them."""
from __future__ import annotations

from dataclasses import dataclass, field

from policies.config.network import NetworkConfig


@dataclass(frozen=True)
class MetaControllerSettings:
    """HRL-SAC's meta-controller: its networks, replay, discount and entropy, what it sees and when it learns."""

    meta_actor: NetworkConfig = field(default_factory=NetworkConfig)
    """Meta actor: meta observation -> hidden -> 4 logits."""
    meta_critic: NetworkConfig = field(default_factory=NetworkConfig)
    """Meta twin critics: meta observation and the goal's one-hot -> hidden -> 1."""
    meta_batch_size: int = 64
    """Meta minibatch (the paper's 64)."""
    meta_buffer_size: int = 50_000
    """Meta replay capacity (K-step transitions)."""
    meta_gamma: float = 0.99
    """Discount per low-level step inside the K-step return; a meta transition is discounted by gamma^k."""
    meta_target_entropy_scale: float = 0.89
    """Meta entropy target = scale * log(4): high enough that the meta-policy never collapses."""
    meta_min_alpha: float = 1e-3
    """Floor on the meta temperature, a second guard against a deterministic meta-policy."""
    meta_updates_per_transition: int = 1
    """Meta-controller gradient updates per completed meta transition (one every K steps per environment)."""
    meta_ignores: tuple[str, ...] = ()
    """Meta observation fields (``autonomy.observation`` names) that the meta-controller's actor and critics ignore
    (an input mask, as ``low_level_ignores``; the input stays as wide). () = it sees everything (the paper). On
    SarSearch-v1 the goals are grounded on the belief map by the search logic, and the meta observation also
    carries the map's summary (``belief_remaining``, ``belief_peak_offset``); its 256 cells are most of the meta
    observation, and what decides between searching on, looking at a candidate and going home lies in the other
    28 values."""
    meta_only_steps: int = 0
    """HRL-SAC: the last this many of ``total_steps`` train the meta-controller alone, against the low level as it
    will fly: the low-level networks and the observation normaliser are frozen, the low level acts with its mean
    action (as an exported policy does), and the meta replay buffer is emptied when this phase starts (its
    transitions came from a low level still learning, with exploration noise). While both levels learn, the
    meta-controller's K-step returns depend on a moving low level; this phase gives it a fixed one. Steps of
    this phase cost no low-level update, so they run several times faster. 0 = off."""
    meta_joint_goals: str = "learned"
    """HRL-SAC's goals while both levels learn: "learned" (the meta-controller's, as in the paper) or "random"
    (uniform, as in the warm-up; the meta-controller then learns only in the meta-only phase, against the low level
    it will fly with, so ``meta_only_steps`` must be above 0). Random goals keep a meta-controller that learns
    against an early, clumsy low level from collapsing onto the goal that costs least per segment (hovering at
    home) while the low level still has everything to learn. On SarSearch-v1, random goals (and the warm-up's)
    are ReturnToBase from the bingo call on (``missions.search_state_v1.BINGO_RESERVE_S``): uniform goals almost
    never bring a drone all the way home, and a low level that never learned to land there could not end a sortie
    at home, whatever the meta-controller chose (docs/training.md, "SarSearch-v1 options")."""
    meta_returned_reward: float | None = None
    """SarSearch-v1: what a return home with reserve pays in the meta-controller's learning reward, in place of the
    environment's +20 (``policies.env.task_v1.REWARD_RETURNED``); None = the environment's. The task, its reward
    and its success are unchanged: only what the meta-controller learns from. Why: +20 for any return after a
    short excursion makes going home at once the meta-controller's easiest return."""
    meta_belief_bonus: float = 0.0
    """SarSearch-v1: the meta-controller's learning reward plus this many times the belief each step's look removed
    (the chance, under the crew's own model, that the look found the victim; the low level's ``belief_bonus``). The
    +100 of a success comes in one step out of hundreds and only in some sorties; the belief removed is its expected
    value as the search goes, so the value of searching on against going home shows in every segment's return
    instead of only in the rare ones that end in a success. The task and its success are unchanged. 0 = off."""
    meta_only_entropy_scale: float = 0.1
    """Meta entropy target in the meta-only phase = scale * log(4). Lower than ``meta_target_entropy_scale``:
    that high target keeps the goals varied while the low level learns to fly them all, but against a fixed
    low level it only makes the meta-controller's values those of a near-random choice of goals."""
