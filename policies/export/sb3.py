"""Export a Stable-Baselines3 SAC model (``model.save``'s zip) to the artifact flat SAC exports produce
(``hrlsac export --from-sb3 MODEL.zip``): the way to fly a policy you trained yourself on SarSearch-v1.

The artifact is the one of :mod:`policies.export.artifact`: a flat policy (``select_goal`` gives -1, no goal) with its
manifest, algorithm ``"sb3-sac"``. Its ``act`` is SB3's deterministic action, operation for operation as
``model.predict(obs, deterministic=True)`` computes it for a Box observation (``stable_baselines3/sac/policies.py``,
``common/policies.py``):

    features = obs                                  preprocess_obs: a float Box passes as it is; FlattenExtractor
    u = tanh(mu(latent_pi(features)))              SquashedDiagGaussianDistribution.mode (gSDE: the same, mu clipped)
    action = low + 0.5 * (u + 1) * (high - low)     BasePolicy.unscale_action, float32 (no clipping: SB3 has none)

What is refused, each with one line naming the problem: a file that is not an SB3 model zip, a model whose policy
is not SAC's, an observation or action space other than SarSearch-v1's (wrappers that change them, SarSearch-v0), a
custom features extractor, and a model trained on VecNormalize-normalised observations (the statistics live in a
separate file, ``vec_normalize.pkl``, and the artifact is fed raw observations). The model zip does not say how the
environment was made, so the caller passes the keyword arguments the model's ``gymnasium.make("SarSearch-v1",
...)`` had (``env_kwargs``: the action frame and the flight settings decide how the runner reads the actions).

Before anything is written, the artifact as the runtime loads it must give SB3's own ``model.predict`` actions, to
float32 rounding, on observations recorded in the environment (``policies.export.parity``). Stable-Baselines3 is an
optional dependency (``pip install stable-baselines3``); loading a model zip unpickles it, so export only models you
trust, as with any pickle.
"""
from __future__ import annotations

import copy
import dataclasses
import enum
import hashlib
import io
import numbers
import zipfile
from pathlib import Path
from types import ModuleType

import numpy as np
import torch
from gymnasium import spaces
from torch import Tensor, nn

from autonomy.observation import LAYOUTS, NO_GOAL, OBS_DIM, OBSERVATION_LAYOUT_VERSION
from autonomy.policy import Policy, one_line
from autonomy.policy_manifest import PolicyManifest, SourceCheckpoint
from missions.mission import FlightSettings
from policies.env.core import ACTION_HIGH, ACTION_LOW, SarSearchConfig
from policies.evaluation.episodes import episode_batch
from policies.export.artifact import (
    ExportResult,
    ParityError,
    artifact_bytes,
    checked_destination,
    flight_manifest,
    write_artifact,
)
from policies.export.module import NoGoal, PolicyModule, check_batch
from policies.export.parity import PARITY_OBSERVATIONS, Parity, compare_with, fly_and_record

SB3_ALGORITHM = "sb3-sac"
"""The manifest's ``algorithm`` (and so the mission report's ``pilot``) of an exported SB3 SAC."""
INSTALL_HINT = "pip install stable-baselines3 (or pip install 'hrlsac[sb3]')"
ENV_KWARGS = ("task", "split", "pool_size", "flight", "action_frame", "goal_conditioned", "max_targets",
              "max_obstacles")
"""The ``gymnasium.make("SarSearch-v1", ...)`` keyword arguments an export accepts (``SarSearchConfig`` fields)."""
MODEL_MEMBERS = ("data", "policy.pth")
"""What ``model.save`` always writes into the zip."""


def import_sb3() -> ModuleType:
    """The ``stable_baselines3`` package, or an ImportError saying how to install it."""
    try:
        import stable_baselines3
    except ImportError:
        raise ImportError(f"exporting a Stable-Baselines3 model needs stable_baselines3: {INSTALL_HINT}") from None
    return stable_baselines3


def environment_config(env_kwargs: dict | None) -> SarSearchConfig:
    """The environment the model was trained in, from its ``gymnasium.make("SarSearch-v1", **env_kwargs)`` keyword
    arguments (``flight`` as an object of ``FlightSettings`` fields); a ValueError names what cannot be flown."""
    values = dict(env_kwargs or {})
    if unknown := sorted(set(values) - set(ENV_KWARGS)):
        raise ValueError(f"env kwargs: {unknown[0]!r} is not accepted (choose from {', '.join(ENV_KWARGS)})")
    values.setdefault("task", "SarSearch-v1")
    try:
        if "flight" in values:
            if not isinstance(values["flight"], dict):
                raise ValueError("flight must be an object of FlightSettings fields, e.g. {\"max_steps\": 1000}")
            values["flight"] = FlightSettings(**values["flight"])
        config = SarSearchConfig(**values)
    except (TypeError, ValueError) as exc:  # an unknown FlightSettings field, a value out of its range, ...
        raise ValueError(f"env kwargs: {str(exc).strip().splitlines()[0]}") from None
    if config.task != "SarSearch-v1":
        raise ValueError(f"env kwargs: task {config.task!r} cannot be flown: the runtime flies SarSearch-v1 "
                         f"(observation layout {OBSERVATION_LAYOUT_VERSION})")
    if config.goal_conditioned:
        raise ValueError("env kwargs: goal_conditioned must be false: an SB3 SAC is flown as a flat policy, whose "
                         "observation's target is the datum (goal_conditioned is HRL-SAC's low level)")
    return config


def read_model(path: Path | str):
    """The SAC model of an SB3 model zip (on the CPU) and the SHA-256 of exactly the bytes it was loaded from."""
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{path}: a folder, not a Stable-Baselines3 model zip (give the file model.save wrote)")
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: no such file") from None
    except OSError as exc:
        raise ValueError(f"{path}: cannot read the file ({exc.strerror})") from None
    try:
        members = zipfile.ZipFile(io.BytesIO(raw)).namelist()
    except Exception:  # BadZipFile, or a damaged directory (UnicodeDecodeError, struct.error, ...)
        raise ValueError(f"{path}: not a Stable-Baselines3 model zip (not a readable zip archive)") from None
    if missing := [name for name in MODEL_MEMBERS if name not in members]:
        raise ValueError(f"{path}: not a Stable-Baselines3 model zip (no {' or '.join(missing)} inside; "
                         "expected a file written by model.save)")
    sb3 = import_sb3()
    from stable_baselines3.common.save_util import load_from_zip_file
    from stable_baselines3.sac.policies import SACPolicy

    try:
        data, _, _ = load_from_zip_file(io.BytesIO(raw), device="cpu")
    except Exception as exc:  # whatever a damaged zip or pickle raises
        raise ValueError(f"{path}: the Stable-Baselines3 model does not load ({one_line(exc)})") from None
    policy_class = (data or {}).get("policy_class")
    if not isinstance(policy_class, type):
        raise ValueError(f"{path}: the model's policy class cannot be read (one defined outside Stable-Baselines3? "
                         "hrlsac exports SB3's SAC MlpPolicy)")
    if not issubclass(policy_class, SACPolicy):
        raise ValueError(f"{path}: not a SAC model (its policy is {policy_class.__name__}; hrlsac exports "
                         "Stable-Baselines3 SAC models only)")
    try:
        model = sb3.SAC.load(io.BytesIO(raw), device="cpu")
    except Exception as exc:
        raise ValueError(f"{path}: the Stable-Baselines3 model does not load ({one_line(exc)})") from None
    return model, hashlib.sha256(raw).hexdigest()


def _box(space) -> str:
    if isinstance(space, spaces.Box):
        return f"Box of shape {space.shape}"
    return type(space).__name__


def check_model(model, name: str) -> None:
    """Refuse (ValueError naming ``name`` and the problem) a model the runtime cannot feed or read."""
    layout = LAYOUTS[OBSERVATION_LAYOUT_VERSION]
    observation = model.observation_space
    if not (isinstance(observation, spaces.Box) and observation.shape == (OBS_DIM,)
            and np.array_equal(observation.low, layout.low) and np.array_equal(observation.high, layout.high)):
        known = [f" (SarSearch-v0's, observation layout {v})" for v, other in LAYOUTS.items()
                 if v != OBSERVATION_LAYOUT_VERSION and getattr(observation, "shape", None) == (other.dim,)]
        raise ValueError(f"{name}: the model's observation space is a {_box(observation)}{''.join(known)}, not "
                         f"SarSearch-v1's ({OBS_DIM} values in [0, 1] or [-1, 1], observation layout "
                         f"{OBSERVATION_LAYOUT_VERSION}): train on gymnasium.make('SarSearch-v1') without "
                         "observation wrappers")
    action = model.action_space
    if not (isinstance(action, spaces.Box) and action.shape == (len(ACTION_LOW),)
            and np.array_equal(action.low, ACTION_LOW) and np.array_equal(action.high, ACTION_HIGH)):
        bounds = (f" from {action.low.tolist()} to {action.high.tolist()}" if isinstance(action, spaces.Box)
                  and action.shape == (len(ACTION_LOW),) else "")
        raise ValueError(f"{name}: the model's action space is a {_box(action)}{bounds}, not SarSearch-v1's (4 "
                         f"actions from {ACTION_LOW.tolist()} to {ACTION_HIGH.tolist()}): train without action "
                         "wrappers")
    extractor = model.policy.actor.features_extractor
    if type(extractor).__name__ != "FlattenExtractor":
        raise ValueError(f"{name}: the model's actor has a custom features extractor ({type(extractor).__name__}); "
                         "hrlsac exports MlpPolicy's (FlattenExtractor)")
    last = getattr(model, "_last_obs", None)  # saved with the model: the last observation training acted on
    if isinstance(last, np.ndarray) and last.shape[-1:] == (OBS_DIM,) and (
            (last < layout.low).any() or (last > layout.high).any()):
        raise ValueError(f"{name}: the model was trained on normalised observations (its last training observation "
                         "lies outside SarSearch-v1's bounds: VecNormalize?); the artifact is fed raw observations "
                         "and the normalisation is not in the model zip: train without VecNormalize(norm_obs=True)")


class SB3ActionHead(nn.Module):
    """Raw observations (N, 288) -> SB3 SAC's deterministic actions (N, 4) (see the module docstring)."""

    def __init__(self, actor: nn.Module, low: np.ndarray, high: np.ndarray):
        super().__init__()
        self.width = OBS_DIM
        self.latent_pi = copy.deepcopy(actor.latent_pi)
        self.mu = copy.deepcopy(actor.mu)  # gSDE: Linear then Hardtanh(-clip_mean, clip_mean), as SB3 has it
        low32, high32 = np.asarray(low, dtype=np.float32), np.asarray(high, dtype=np.float32)
        self.register_buffer("low", torch.from_numpy(low32.copy()))
        self.register_buffer("span", torch.from_numpy(high32 - low32))  # (high - low) in float32, as SB3's numpy

    def forward(self, obs: Tensor) -> Tensor:
        check_batch(obs, self.width)  # a (N, 288) float batch: FlattenExtractor and preprocess_obs leave it as is
        unit = torch.tanh(self.mu(self.latent_pi(obs)))
        return self.low + 0.5 * (unit + 1.0) * self.span


def sb3_module(model) -> PolicyModule:
    """The exportable module of an SB3 SAC ``model`` (copies of its actor's layers, in evaluation mode)."""
    head = SB3ActionHead(model.policy.actor, model.action_space.low, model.action_space.high)
    return PolicyModule(head, NoGoal()).eval().requires_grad_(False)


def _plain(value):
    """A JSON value for a manifest entry: numbers, strings, booleans and None as they are, enums by their value,
    sequences and mappings item by item, anything else (a class, a schedule) by its name."""
    if value is None or isinstance(value, (str, bool)):
        return value
    if isinstance(value, enum.Enum):  # e.g. train_freq's TrainFrequencyUnit
        return _plain(value.value)
    if isinstance(value, numbers.Number):
        return value.item() if isinstance(value, np.generic) else value
    if isinstance(value, (list, tuple)):
        return [_plain(item) for item in value]
    if isinstance(value, dict):
        return {str(key): _plain(item) for key, item in value.items()}
    return getattr(value, "__name__", None) or str(value)


def training_config(model, config: SarSearchConfig, env_kwargs: dict | None, version: str) -> dict:
    """The manifest's ``training_config``: what the runner reads (``task``, ``action_frame``, ``flight``), the seed,
    the trainer, the environment's keyword arguments and SB3's own settings."""
    actor = model.policy.actor
    settings = {name: _plain(getattr(model, name, None)) for name in (
        "learning_rate", "buffer_size", "learning_starts", "batch_size", "tau", "gamma", "train_freq",
        "gradient_steps", "ent_coef", "target_update_interval", "target_entropy", "use_sde", "n_envs")}
    settings.update(policy=type(model.policy).__name__, net_arch=_plain(actor.net_arch),
                    activation_fn=actor.activation_fn.__name__, policy_kwargs=_plain(model.policy_kwargs))
    return {"algo": SB3_ALGORITHM, "trainer": f"stable-baselines3 {version}", "task": config.task,
            "action_frame": config.action_frame, "split": config.split, "seed": _plain(model.seed),
            "flight": dataclasses.asdict(config.flight), "env_kwargs": _plain(env_kwargs or {}),
            "stable_baselines3": settings}


def build_sb3_manifest(model, config: SarSearchConfig, env_kwargs: dict | None, fmt: str, source_name: str,
                       sha256: str) -> PolicyManifest:
    """The manifest of an SB3 SAC ``model`` trained in ``config``, exported from the zip ``source_name``."""
    version = import_sb3().__version__
    return flight_manifest(fmt, SB3_ALGORITHM, config.action_frame, training_config(model, config, env_kwargs, version),
                           SourceCheckpoint(source_name, sha256, int(model.num_timesteps)))


def sb3_parity(model, artifact: Policy, config: SarSearchConfig, count: int = PARITY_OBSERVATIONS,
               envs: int = 100, seed: int = 0) -> Parity:
    """The loaded ``artifact`` against SB3's own ``model.predict(obs, deterministic=True)`` on ``count`` observations
    recorded by flying the model (and random actions) on the val split of ``config``'s environment."""
    def predict(obs: np.ndarray) -> np.ndarray:
        return model.predict(obs, deterministic=True)[0]

    core = episode_batch("val", envs, config.flight, goal_conditioned=False, task=config.task,
                         action_frame=config.action_frame)
    obs = fly_and_record(core, predict, count, seed)
    return compare_with(predict(obs), np.full(len(obs), NO_GOAL), artifact, obs)


def export_sb3_policy(model_zip: Path | str, out: Path | str, fmt: str = "torchscript",
                      env_kwargs: dict | None = None, observations: int = PARITY_OBSERVATIONS) -> ExportResult:
    """Write the artifact of the SB3 SAC model in ``model_zip``, trained in ``gymnasium.make("SarSearch-v1",
    **env_kwargs)``, to ``out``, after checking it against SB3's ``predict`` on ``observations`` recorded
    observations (``ParityError`` and nothing written if it disagrees)."""
    out = checked_destination(out)
    config = environment_config(env_kwargs)
    model, sha256 = read_model(model_zip)
    check_model(model, str(model_zip))
    manifest = build_sb3_manifest(model, config, env_kwargs, fmt, Path(model_zip).name, sha256)
    try:
        data = artifact_bytes(sb3_module(model), manifest)
    except Exception as exc:  # an activation or layer TorchScript / torch.export cannot take
        raise ValueError(f"{model_zip}: the model's actor does not export to {fmt} ({one_line(exc)})") from None

    def parity_of(artifact: Policy) -> Parity:
        parity = sb3_parity(model, artifact, config, observations)
        if not parity.ok:
            raise ParityError(f"parity check with Stable-Baselines3's predict failed: {parity.summary()}; "
                              "nothing written")
        return parity

    return ExportResult(out, manifest, len(data), write_artifact(out, data, parity_of))
