"""``TrainConfig``: every setting of a training run in one frozen dataclass, checked as a whole, with the presets
and the ``config.json`` form. Its fields are grouped by concern in the classes it is made of, which document
each one: the run (``policies.config.run``), the continuous SAC and replay (``policies.config.low_level``),
the meta-controller (``policies.config.hrl``), the learning rewards (``policies.config.shaping``) and the
bookkeeping (``policies.config.run``), in that order in ``config.json``."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from autonomy.observation import LAYOUT_V3, LAYOUT_V4, ObservationLayout
from missions.action_frames import check_action_frame
from missions.mission import FlightSettings
from missions.validation import check_choice, check_fields
from policies.config.hrl import MetaControllerSettings
from policies.config.low_level import ReplaySettings, SacSettings
from policies.config.network import NetworkConfig
from policies.config.run import BookkeepingSettings, RunSettings
from policies.config.shaping import ShapingSettings


# The bases in reverse: a dataclass lists the fields of its bases from the last one to the first.
@dataclass(frozen=True)
class TrainConfig(BookkeepingSettings, ShapingSettings, MetaControllerSettings, ReplaySettings, SacSettings,
                  RunSettings):
    """Everything that defines a training run; ``hrlsac train`` writes it to the run folder."""

    def __post_init__(self) -> None:
        for name, choices in (("algo", ("hrl-sac", "sac")), ("task", ("SarSearch-v0", "SarSearch-v1")),
                              ("update_dtype", ("float32", "bfloat16")), ("intrinsic_reward", ("progress", "distance")),
                              ("meta_joint_goals", ("learned", "random"))):
            check_choice("TrainConfig", name, getattr(self, name), choices)
        self._check_ignores("low_level_ignores", "observation", list(self.layout.by_name))
        meta_fields = [f.name for f in self.layout.fields if f.name != "goal"]
        self._check_ignores("meta_ignores", "meta observation", meta_fields)
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
