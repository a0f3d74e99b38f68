"""Every hyper-parameter of HRL-SAC and flat SAC in one dataclass, with the paper's and our presets.

``TrainConfig.from_preset("paper")`` follows the paper's tables (3 x 512 low-level networks with LayerNorm, ReLU and
Dropout 0.1; 2 x 256 meta networks; Adam 3e-4; gamma 0.99; tau 0.005; K = 30; batches 128 / 64; prioritised
replay; 2,000 warm-up steps). ``"default"`` keeps the structure but is sized for a 2-core CPU: 2 x 256
low-level networks without dropout (measured here: a paper-sized SAC update runs at 10-15 per second on one
core, Dropout alone costs about a third of it; 2 x 256 networks run at 50-90 per second).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from autonomy.observation import LAYOUT_V3, LAYOUT_V4, ObservationLayout
from missions.action_frames import check_action_frame
from missions.mission import FlightSettings
from missions.validation import Interval, check_choice, check_fields


@dataclass(frozen=True)
class NetworkConfig:
    """Shape of one family of networks (actor and critics share it)."""

    hidden: tuple[int, ...] = (256, 256)
    """Widths of the hidden layers (each Linear -> LayerNorm -> ReLU -> Dropout)."""
    head: int | None = None
    """Width of an extra last hidden layer before the output (the paper's 256 after 3 x 512); None = none."""
    layer_norm: bool = True
    """LayerNorm after each hidden Linear (the paper: yes)."""
    dropout: float = 0.0
    """Dropout probability after each hidden activation (the paper: 0.1). Off in deterministic evaluation."""

    def __post_init__(self) -> None:
        if not self.hidden or any(int(w) != w or w < 1 for w in self.hidden):
            raise ValueError(f"NetworkConfig.hidden must be positive integers, got {self.hidden}")
        check_fields(self, (("dropout", Interval(0.0, 1.0, high_open=True)),))

    @property
    def layers(self) -> tuple[int, ...]:
        return tuple(self.hidden) + ((self.head,) if self.head else ())


@dataclass(frozen=True)
class TrainConfig:
    """Everything that defines a training run; ``hrlsac train`` writes it to the run folder."""

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

    # --- low-level / flat SAC
    actor: NetworkConfig = field(default_factory=NetworkConfig)
    """Low-level (or flat) actor: 276 -> hidden -> (mean, log_std) of 4."""
    critic: NetworkConfig = field(default_factory=NetworkConfig)
    """Low-level twin critics: 276 + 4 -> hidden -> 1."""
    learning_rate: float = 3e-4
    """Adam learning rate of every network and of the entropy temperatures (the paper's table)."""
    gamma: float = 0.99
    """Discount of flat SAC (the paper's 0.99)."""
    low_level_gamma: float = 0.95
    """Discount of HRL-SAC's goal-conditioned low level (the paper preset: 0.99). Re-grounded goals make its
    return an endless chain of +1 per step of progress, so with 0.99 the critic's values (~100) dwarf the effect
    of one action and the low level flies slowly; 0.95 keeps one action's effect visible (measurements:
    docs/training.md, "How the defaults were chosen")."""
    tau: float = 0.005
    """Polyak rate of the target critics."""
    batch_size: int = 128
    """Low-level minibatch."""
    buffer_size: int = 100_000
    """Low-level replay capacity (transitions; about 2.2 kB each, kept in checkpoints)."""
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
    critics ignore: their inputs are multiplied by 0 (``networks.InputMask``), so the input stays 276 wide. Where
    to search is the meta-controller's choice; a low level that sees the coverage map learns to dawdle over it
    instead of flying to its goal. Flat SAC ignores this field (it plans the search itself). The paper preset: () (the low level sees everything). SarSearch-v0's
    map field is "coverage", v1's "belief"."""

    update_dtype: str = "float32"
    """Precision of the hidden layers' matrix products in low-level / flat SAC updates: "float32" (the default, and
    what every comparison in docs/results trained with) or "bfloat16" (weights, Adam, outputs and losses stay
    float32, acting stays float32; faster on CPUs with AVX-512 BF16 or AMX, slower without). bfloat16 is a speed
    option, not a free one: on the easy missions of tests/test_learning.py HRL-SAC learned in 6 of 6 seeds in
    float32 and in 2 of 6 in bfloat16 (docs/training.md, "update_dtype"). The two round differently: each is
    reproducible on a given CPU, they are not bit-equal."""

    # --- prioritised replay (both levels)
    per_alpha: float = 0.6
    """How strongly priorities skew sampling (0 = uniform)."""
    per_beta_start: float = 0.4
    """Importance-weight exponent at the start, annealed linearly to 1 over the run (over the steps before the
    meta-only phase, ``meta_only_steps``; 1 during it)."""
    per_eps: float = 1e-6
    """Added to |TD error| so that no transition gets priority 0."""

    # --- meta-controller (HRL-SAC)
    meta_actor: NetworkConfig = field(default_factory=NetworkConfig)
    """Meta actor: 272 -> hidden -> 4 logits."""
    meta_critic: NetworkConfig = field(default_factory=NetworkConfig)
    """Meta twin critics: 272 + 4 (goal one-hot) -> hidden -> 1."""
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
    are ReturnToBase from the bingo call on (``missions.search_state_v1.BINGO_RESERVE_S``): uniform goals almost never
    bring a drone all the way home, and a low level that never learned to land there could not end a sortie at
    home, whatever the meta-controller chose (docs/results/README.md, the v1 probes)."""
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
    intrinsic_reward: str = "progress"
    """Low-level reward towards the goal point g: "distance" is the paper's -||s' - g|| / intrinsic_scale_m;
    "progress" is (||s - g|| - ||s' - g||) / intrinsic_scale_m, the same signal as potential-based shaping.
    With "distance" every step costs, so ending the episode early by leaving the area (-10 once) beats a long
    flight to a far goal. See docs/paper-notes.md."""
    intrinsic_scale_m: float = 10.0
    """Metres per unit of intrinsic reward. 10 m makes a full-speed step towards g worth +1, well above the entropy
    bonus."""
    cross_track_penalty: float = 0.0
    """Low-level reward minus this many times the distance flown across the line to g this step (metres, per
    ``intrinsic_scale_m``): the sideways part of the step, |d x u| for the step d and the unit vector u from the
    drone to g. The progress reward alone barely tells a heading 30 degrees off from a straight one (cos 30 = 0.87 of
    the progress); with 1, a full-speed step 30 degrees off earns 0.37 instead of 0.87. Routed goal points (round
    danger zones, inside the fence margin) are only safe flown straight. 0 = off, the default (the paper has no
    such term); the comparison presets use 1."""
    intrinsic_goal_bonus: float = 1.0
    """Added to the intrinsic reward on the step the low level completes its sub-goal: it comes within reach of
    the point and the goal, grounded again, points elsewhere (the cell got searched, the search moved on).
    Being within reach of a point that stays put (sensor off over an unsearched cell, home) earns nothing."""
    extrinsic_weight: float = 0.0
    """Share of the extrinsic reward added to the low-level reward (0 = purely intrinsic, as the paper), without
    its constant per-step cost: with that cost, ending the episode early by leaving the area (-10 once) is worth
    about as much as a long flight, and a pilot run learned to leave (the time cost is the meta-controller's)."""
    coverage_bonus: float = 0.3
    """Low-level reward per newly covered grid cell (0 = none): the only part of the low-level reward that pays
    for keeping the search sensor on (a cell counts as covered only with the sensor on). Too small a bonus and the
    deterministic low level keeps the sensor off."""
    coverage_by_intensity: bool = False
    """Each newly covered cell earns ``coverage_bonus`` times the search intensity it was covered with, instead of
    the whole bonus (the detection probability is proportional to the intensity, while a cell counts as covered at
    any intensity >= 0.5). Off by default: it raises the learned intensity, as meant, but not the success."""
    belief_bonus: float = 0.0
    """SarSearch-v1: low-level (and, with ``flat_shaping``, flat) reward plus this many times the belief the step's
    look removed (``info["belief_removed"]``): the chance, under the crew's own model, that the look found the
    victim, so with 100 (the success reward) it pays the expected value of the look. It reads only what the crew
    knows. 0 = off."""
    identify_bonus: float = 0.0
    """SarSearch-v1: learning reward plus this many times the chance, under the crew's model, that the step's close
    look identified an unresolved candidate (``info["identify_chance"]``: the identification probability at the
    candidates' estimates, 0 above the close-look speed). It pays for what a close look needs (a hover, zoom,
    the sensor on) where the goal bonus pays only once the candidate is resolved. 0 = off."""
    flat_shaping: bool = False
    """Flat SAC learns from the shaping the HRL low level gets, towards the observation's target (TrackObject's
    point: a candidate, else the most probable place): the progress to it, the cross-track penalty, the coverage
    and belief bonuses, and the environment reward without its per-step cost (so leaving the area early, -10, is
    never worth more than searching). False = the environment reward alone (the paper's flat SAC)."""
    n_step: int = 1
    """Continuous SAC (flat or low level): n-step returns, the reward of n steps discounted and the bootstrap by
    gamma^n (cut short at an episode's end). 1 = one-step SAC."""
    detection_bonus: float = 0.0
    """Low-level reward times the probability that this step detects the victim for the first time (its
    detection probability where it is in the camera's view, 0 once it has been detected): the expected value of
    the detection the search is for, which pays for what the sensor settings do (intensity, zoom against the
    footprint's width) where the coverage bonus cannot tell. The probability uses the hidden victim, as the
    environment's own reward does; it is a training signal only, never an input. 0 = off, the default: it keeps
    the sensor on more without a better success."""
    coverage_swept: bool = False
    """The coverage bonus counts the ground the camera footprint swept this step (distance flown x footprint
    width, in grid cells, sensor on) instead of the newly covered cells. The low level does not see the coverage
    map, so whether a cell is new is noise to it; the swept ground pays directly for what it controls: speed, the
    sensor switched on and a wide footprint (zoom out). Where to search stays the goals' business. Off by default
    (probed on one seed only, no gain)."""

    # --- bookkeeping
    checkpoint_every: int = 20_000
    """Environment steps between checkpoints (written atomically; --resume continues from the last)."""
    eval_every: int = 10_000
    """Environment steps between quick evaluations: the deterministic policy as it stands flies the first
    ``eval_episodes`` scenarios of the val split; the success rate is logged (``eval_success_rate``). They use
    no random generator of the run, so they do not change its training. 0 = never."""
    eval_episodes: int = 32
    """Episodes per quick evaluation (500 take about 8 s here with a trained HRL-SAC policy: 7.3 and 7.8 s
    measured)."""
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
    """Quick evaluations (and so ``meta_keep_best`` and ``keep_best``) fly with the mission runner's rules instead of training's: a
    ReturnToBase decision ends the search and so does the pilot's bingo failsafe (SarSearch-v1;
    ``hrlsac evaluate --flight-rules``). The meta-controller is then chosen by the success it would have in flight,
    where running dry cannot happen, instead of by a trade of success against sorties that ran dry."""
    meta_keep_best_max_ran_dry: float = 1.0
    """With ``meta_keep_best`` or ``keep_best``: only evaluations in which at most this share of the sorties ran dry compete on
    success (while none qualifies, the one with the fewest wins), the rule the scripted searchers are tuned with
    (``benchmarks/tune_baselines.py``, 0.01). 1 = success alone. Choosing on success alone picks a meta-controller
    that never sends the drone home: coming home in time can only end a search sooner."""
    log_every: int = 1_000
    """Environment steps between CSV / TensorBoard log rows."""
    torch_threads: int = 1
    """torch.set_num_threads: 1 is fastest for these small networks on a shared 2-core machine."""

    def __post_init__(self) -> None:
        for name, choices in (("algo", ("hrl-sac", "sac")), ("task", ("SarSearch-v0", "SarSearch-v1")),
                              ("update_dtype", ("float32", "bfloat16")), ("intrinsic_reward", ("progress", "distance")),
                              ("meta_joint_goals", ("learned", "random"))):
            check_choice("TrainConfig", name, getattr(self, name), choices)
        self._check_ignores("low_level_ignores", "observation", list(self.layout.by_name))
        self._check_ignores("meta_ignores", "meta observation", [f.name for f in self.layout.fields if f.name != "goal"])
        counts = (("total_steps", 1, 10**10), ("num_envs", 1, 4096), ("batch_size", 1, 65536),
                  ("meta_batch_size", 1, 65536), ("buffer_size", 1, 10**8), ("meta_buffer_size", 1, 10**8),
                  ("warmup_steps", 0, 10**9), ("seed", 0, 2**32 - 1), ("meta_updates_per_transition", 1, 64),
                  ("meta_only_steps", 0, 10**10), ("n_step", 1, 64), ("eval_every", 0, 10**10),
                  ("eval_episodes", 1, 100_000))
        check_fields(self, counts, integers=[name for name, _, _ in counts])
        check_fields(self, (("learning_rate", 1e-7, 1.0), ("gamma", 0.0, 1.0), ("low_level_gamma", 0.0, 1.0),
                            ("meta_gamma", 0.0, 1.0), ("tau", 0.0, 1.0), ("updates_per_step", 0.0, 64.0),
                            ("per_alpha", 0.0, 1.0), ("per_beta_start", 0.0, 1.0),
                            ("meta_target_entropy_scale", 0.0, 1.0), ("meta_only_entropy_scale", 0.0, 1.0),
                            ("initial_alpha", 1e-6, 100.0), ("intrinsic_scale_m", 1e-3, 1e6),
                            ("cross_track_penalty", 0.0, 1e3), ("coverage_bonus", 0.0, 1e3),
                            ("detection_bonus", 0.0, 1e3), ("belief_bonus", 0.0, 1e4), ("identify_bonus", 0.0, 1e4),
                            ("meta_belief_bonus", 0.0, 1e4),
                            ("action_margin", 0.0, 1.0), ("meta_keep_best_max_ran_dry", 0.0, 1.0)))
        if self.meta_returned_reward is not None:  # None: the environment's
            check_fields(self, (("meta_returned_reward", -1e3, 1e3),))
        if self.meta_returned_reward is not None and self.task != "SarSearch-v1":
            raise ValueError(f"TrainConfig.meta_returned_reward applies to SarSearch-v1 only (its return home), got "
                             f"{self.meta_returned_reward!r} on {self.task}; leave it unset (None)")
        if self.meta_belief_bonus and self.task != "SarSearch-v1":
            raise ValueError(f"TrainConfig.meta_belief_bonus applies to SarSearch-v1 only (its belief), got "
                             f"{self.meta_belief_bonus!r} on {self.task}; leave it at 0")
        check_action_frame("TrainConfig", self.action_frame, self.task)
        if self.meta_joint_goals == "random" and self.meta_only_steps <= 0 and self.algo == "hrl-sac":
            raise ValueError("TrainConfig.meta_joint_goals 'random' needs a meta-only phase for the meta-controller to "
                             "learn in: set meta_only_steps above 0")
        if self.meta_keep_best and (self.eval_every <= 0 or self.meta_only_steps <= 0):
            raise ValueError("TrainConfig.meta_keep_best needs a meta-only phase and quick evaluations to choose "
                             f"from: set meta_only_steps and eval_every above 0 (got {self.meta_only_steps} and "
                             f"{self.eval_every})")
        if self.keep_best and (self.algo != "sac" or self.eval_every <= 0):
            raise ValueError("TrainConfig.keep_best is the flat SAC's and chooses among quick evaluations: use it with "
                             f"algo 'sac' and eval_every above 0 (got {self.algo!r} and {self.eval_every}); "
                             "HRL-SAC keeps its best meta-controller with meta_keep_best")
        if self.meta_only_steps >= self.total_steps:
            raise ValueError(f"TrainConfig.meta_only_steps ({self.meta_only_steps:,}) must be below total_steps "
                             f"({self.total_steps:,}): the low level has to learn before the meta-controller "
                             f"trains alone against it")

    @property
    def meta_only_from(self) -> int:
        """The environment step from which only the meta-controller learns (``total_steps`` when never)."""
        return self.total_steps - self.meta_only_steps if self.algo == "hrl-sac" else self.total_steps

    @property
    def layout(self) -> ObservationLayout:
        """The observation layout of the task trained on (version 3 for SarSearch-v0, 4 for v1)."""
        return LAYOUT_V3 if self.task == "SarSearch-v0" else LAYOUT_V4

    @property
    def low_level_input_mask(self) -> np.ndarray | None:
        """(obs_dim,) 0 / 1: the observation features the continuous SAC's networks see; None = all of them."""
        return self._input_mask(self.low_level_ignores, self.layout.dim) if self.algo == "hrl-sac" else None

    @property
    def meta_input_mask(self) -> np.ndarray | None:
        """(meta_dim,) 0 / 1: the meta observation features the meta-controller's networks see; None = all."""
        return self._input_mask(self.meta_ignores, self.layout.meta_dim)

    def _input_mask(self, ignores: tuple[str, ...], width: int) -> np.ndarray | None:
        """(width,) ones, with zeros over the ``ignores`` fields of the layout; None when nothing is ignored."""
        if not ignores:
            return None
        keep = np.ones(width, dtype=np.float32)
        for name in ignores:
            keep[self.layout.by_name[name].slice] = 0.0
        return keep

    def _check_ignores(self, field_name: str, what: str, names: list[str]) -> None:
        """One ValueError unless the ``field_name`` setting is a list of these ``names``."""
        ignores = getattr(self, field_name)
        if isinstance(ignores, str) or any(name not in names for name in ignores):
            raise ValueError(f"TrainConfig.{field_name} must be a list of {self.task} {what} field names "
                             f"({', '.join(names)}), got {ignores!r}")

    @property
    def sac_gamma(self) -> float:
        """The discount of the continuous SAC this config trains: the low level's (HRL-SAC) or flat SAC's."""
        return self.low_level_gamma if self.algo == "hrl-sac" else self.gamma

    @classmethod
    def from_preset(cls, name: str, **overrides) -> "TrainConfig":
        """The "default" (CPU-sized) or "paper" configuration, with field overrides."""
        if name == "default":
            base = cls(preset="default")
        elif name == "paper":
            big = NetworkConfig(hidden=(512, 512, 512), head=256, layer_norm=True, dropout=0.1)
            meta = NetworkConfig(hidden=(256, 256), layer_norm=True, dropout=0.1)
            base = cls(preset="paper", low_level_gamma=0.99, update_dtype="float32", low_level_ignores=(), actor=big,
                       critic=NetworkConfig(hidden=(512, 512), head=256, dropout=0.1),
                       meta_actor=meta, meta_critic=meta, flight=FlightSettings(max_steps=10_000))
        else:
            raise ValueError(f"unknown preset {name!r} (choose from default, paper)")
        if overrides.get("task") == "SarSearch-v0" and "low_level_ignores" not in overrides and base.low_level_ignores:
            overrides["low_level_ignores"] = ("coverage",)  # v0's map field
        return dataclasses.replace(base, **overrides)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "TrainConfig":
        data = dict(data)
        data["flight"] = FlightSettings(**data["flight"])
        for name in ("actor", "critic", "meta_actor", "meta_critic"):
            data[name] = NetworkConfig(**{**data[name], "hidden": tuple(data[name]["hidden"])})
        data["log_std_bounds"] = tuple(data["log_std_bounds"])
        data["missions"] = tuple(data.get("missions", ()))
        data.setdefault("task", "SarSearch-v0")  # runs from before SarSearch-v1 trained on v0
        ignores = data.get("low_level_ignores", ())  # runs from before the field saw everything
        data["low_level_ignores"] = (ignores,) if isinstance(ignores, str) else tuple(ignores)
        data["meta_ignores"] = tuple(data.get("meta_ignores", ()))
        return cls(**data)
