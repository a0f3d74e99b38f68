"""The settings of a training run as a whole (``RunSettings``: what is trained, on what, how long) and of what it
records on the way (``BookkeepingSettings``: checkpoints, quick evaluations, logs); fields of ``TrainConfig``,
which checks them."""
from __future__ import annotations

from dataclasses import dataclass, field

from missions.mission import FlightSettings


@dataclass(frozen=True)
class RunSettings:
    """The algorithm, the task and its scenarios, the seed, the length and the parallel environments of a run."""

    algo: str = "hrl-sac"
    """"hrl-sac" (meta-controller + goal-conditioned SAC) or "sac" (flat SAC on the same observation)."""
    task: str = "SarSearch-v1"
    """The environment version trained on: "SarSearch-v1" (docs/environment.md) or "SarSearch-v0" (the paper's task;
    runs written before the field existed were trained on it and load as such)."""
    preset: str = "default"
    """Name of the preset this config started from ("default" or "paper"); informational."""
    seed: int = 0
    """Seeds the networks, the replay sampling, exploration and the environments' episode seeds."""
    total_steps: int = 100_000
    """Environment steps to train for (summed over the parallel environments)."""
    num_envs: int = 8
    """Environments stepped together (vectorised); each step adds num_envs transitions."""
    split: str = "train"
    """Scenario split trained on (evaluation uses val / test)."""
    missions: tuple[str, ...] = ()
    """Mission files whose scenarios are trained on instead of the generator's split (flight settings still
    come from ``flight``)."""
    flight: FlightSettings = field(default_factory=FlightSettings)
    """Altitude, speed, decision period, K (subgoal_interval), step limit and reach radius."""
    action_frame: str = "north_east"
    """How the policy's movement is read (``SarSearchConfig.action_frame``, ``missions.action_frames.ACTION_FRAMES``):
    "north_east" (the paper's), or on SarSearch-v1 "target" (towards the observation's target point and to its
    right) or "arrive" (as "target", slowing on the last step so that the constant action (1, 0) stops on the
    target); the exported artifact's manifest carries it and the flight pilot reads it the same way."""


@dataclass(frozen=True)
class BookkeepingSettings:
    """Checkpoints, quick evaluations (and the best policy they keep), logs and threads."""

    checkpoint_every: int = 20_000
    """Environment steps between checkpoints (written atomically; --resume continues from the last)."""
    eval_every: int = 10_000
    """Environment steps between quick evaluations: the deterministic policy as it stands flies the first
    ``eval_episodes`` scenarios of the val split; the success rate is logged (``eval_success_rate``). They use
    no random generator of the run, so they do not change its training. 0 = never."""
    eval_episodes: int = 32
    """Episodes per quick evaluation: more give a steadier success rate (model selection with ``meta_keep_best``
    wants a few hundred), at the cost of the time they take."""
    meta_keep_best: bool = False
    """HRL-SAC with a meta-only phase: the run ends with the meta-controller (its actor, the part that acts) of the
    quick evaluation with the highest val success within the phase, counting the one at its first step (the
    meta-controller of the joint phase), instead of the last one. Model selection on the val split (as
    Stable-Baselines3's EvalCallback keeps its best model), so the test split stays untouched; it needs
    ``eval_every`` > 0, and it judges best with ``eval_episodes`` episodes (use a few hundred)."""
    keep_best: bool = False
    """Flat SAC: the run ends with the policy (its actor and the observation normaliser it was trained with) of
    the quick evaluation that scored best over the whole run, by ``meta_keep_best``'s rule (and its ran-dry limit),
    instead of the last one: the model selection on val that HRL-SAC's meta-controller gets, for a fair
    comparison. Training itself is unchanged; it needs ``eval_every`` > 0. HRL-SAC uses ``meta_keep_best``."""
    eval_flight_rules: bool = False
    """Quick evaluations (and so ``meta_keep_best`` and ``keep_best``) fly with the mission runner's rules instead
    of training's: a ReturnToBase decision ends the search and so does the pilot's bingo failsafe (SarSearch-v1;
    ``hrlsac evaluate --flight-rules``). The meta-controller is then chosen by the success it would have in flight,
    where running dry cannot happen, instead of by a trade of success against sorties that ran dry."""
    meta_keep_best_max_ran_dry: float = 1.0
    """With ``meta_keep_best`` or ``keep_best``: only evaluations in which at most this share of the sorties ran dry
    compete on success (while none qualifies, the one with the fewest wins), the rule the scripted searchers are
    tuned with (``benchmarks/tune_baselines.py``, 0.01). 1 = success alone. Choosing on success alone picks a
    meta-controller that never sends the drone home: coming home in time can only end a search sooner."""
    log_every: int = 1_000
    """Environment steps between CSV / TensorBoard log rows."""
    torch_threads: int = 1
    """torch.set_num_threads: these networks are too small to gain from more threads, and runs trained side by
    side each keep to their own core."""
