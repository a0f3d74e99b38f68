"""The manifest of an exported policy: what a companion computer must know to fly it, inside the artifact.

A policy file is only safe to fly if the runtime feeds it the observation it was trained on and reads its
actions the way it was trained to emit them. The manifest carries that contract (observation layout, action
spec, goals and K) beside the provenance (training config, evaluation metrics, source checkpoint hash, torch
version, time of export), as JSON inside the artifact (see docs/export.md). The exporter
(``policies.export.artifact``) writes it; the runtime (``autonomy.policy``) reads and checks it before loading weights.

``FORMAT_VERSION`` counts incompatible changes of the artifact (the programs' interface or the manifest's
fields); a runtime refuses versions it does not know. Adding a manifest field is not such a change: readers
ignore fields they do not know, and a field added with a default reads as that default from manifests written
before it (``precision`` and ``action_tolerance``: those artifacts are float32).
"""
from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from typing import Any, Callable

from autonomy.observation import META_OBS_DIM, OBS_DIM, OBSERVATION_LAYOUT_VERSION, layout_description

FORMAT_VERSION = 1
FORMATS = ("torchscript", "torch-export")
MANIFEST_FILE = "manifest.json"
NOT_EVALUATED = "not evaluated"


@dataclass(frozen=True)
class ObservationSpec:
    """The observation layout the policy was trained on (``autonomy.observation``)."""

    layout_version: int
    dim: int
    meta_dim: int
    fields: tuple[dict, ...]
    """One dict per field: name, offset, size, description."""

    @classmethod
    def current(cls) -> "ObservationSpec":
        """The layout this code builds."""
        return cls(OBSERVATION_LAYOUT_VERSION, OBS_DIM, META_OBS_DIM, tuple(layout_description()))

    def difference(self, other: "ObservationSpec") -> str | None:
        """None when both describe the same vector (descriptions may differ), else what differs first."""
        for name in ("layout_version", "dim", "meta_dim"):
            if getattr(self, name) != getattr(other, name):
                return f"{name} {getattr(self, name)} vs {getattr(other, name)}"
        placed = [[(f["name"], f["offset"], f["size"]) for f in spec.fields] for spec in (self, other)]
        for mine, theirs in zip(*placed):
            if mine != theirs:
                return (f"field {mine[0]!r} at offset {mine[1]} size {mine[2]} vs "
                        f"{theirs[0]!r} at offset {theirs[1]} size {theirs[2]}")
        if len(placed[0]) != len(placed[1]):
            return f"{len(placed[0])} fields vs {len(placed[1])}"
        return None


@dataclass(frozen=True)
class ActionSpec:
    """What each of the policy's outputs means."""

    names: tuple[str, ...]
    low: tuple[float, ...]
    high: tuple[float, ...]
    units: tuple[str, ...]


@dataclass(frozen=True)
class GoalSpec:
    """One meta-controller goal: its index in ``select_goal``'s output and how the runtime grounds it."""

    index: int
    name: str
    grounding: str


@dataclass(frozen=True)
class SourceCheckpoint:
    """The training checkpoint the artifact was exported from."""

    file: str
    sha256: str
    trained_steps: int


@dataclass(frozen=True)
class PolicyManifest:
    """Everything in ``manifest.json``; see docs/export.md for an example."""

    format_version: int
    format: str
    """"torchscript" or "torch-export"."""
    algorithm: str
    """"hrl-sac" (meta-controller + low level), "sac" (flat: ``select_goal`` returns -1, no goal) or "sb3-sac" (a
    Stable-Baselines3 SAC, flat like "sac"; ``training_config`` then names its trainer and SB3's settings)."""
    subgoal_interval: int | None
    """K, low-level steps between goal decisions; None for flat SAC."""
    goals: tuple[GoalSpec, ...]
    """The meta-controller's goals (empty for flat SAC)."""
    observation: ObservationSpec
    action: ActionSpec
    entry_points: dict[str, str]
    """Entry point name -> signature, in words."""
    training_config: dict[str, Any]
    evaluation: dict[str, Any] | str
    """Split -> metrics of ``hrlsac evaluate`` for this very checkpoint, or "not evaluated"."""
    source_checkpoint: SourceCheckpoint
    torch_version: str
    created_at: str
    """UTC, ISO 8601."""
    precision: str = "float32"
    """The networks' arithmetic: "float32" (as trained) or "int8" (the low-level actor's hidden layers with int8
    weights and bfloat16 activations; docs/export.md, "Precision")."""
    action_tolerance: float = 1e-6
    """Largest |action difference| from the trained policy that the export's parity check accepted (goals are
    always identical)."""

    @property
    def hierarchical(self) -> bool:
        return self.subgoal_interval is not None

    def to_json(self) -> str:
        return json.dumps(dataclasses.asdict(self), indent=2)

    @classmethod
    def from_json(cls, text: str | bytes) -> "PolicyManifest":
        """Parse and check the structure; a ValueError names the problem (unknown version, missing field)."""
        try:
            data = json.loads(text)
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise ValueError(f"manifest is not valid JSON ({exc})") from None
        if not isinstance(data, dict):
            raise ValueError("manifest is not a JSON object")
        version = data.get("format_version")
        if version != FORMAT_VERSION:
            raise ValueError(f"unknown artifact format version {version!r} (this runtime reads version "
                             f"{FORMAT_VERSION}); export the policy again with this version of hrlsac")
        manifest = _build(cls, data, "manifest")
        if manifest.format not in FORMATS:
            raise ValueError(f"manifest format {manifest.format!r} is not one of {', '.join(FORMATS)}")
        if manifest.subgoal_interval is not None and manifest.subgoal_interval < 1:
            raise ValueError(f"manifest subgoal_interval must be at least 1, got {manifest.subgoal_interval}")
        return manifest


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _is_list_of(kind: Callable[[Any], bool]) -> Callable[[Any], bool]:
    return lambda value: isinstance(value, list) and all(kind(item) for item in value)


def _is_dict_of(kind: Callable[[Any], bool]) -> Callable[[Any], bool]:
    return lambda value: isinstance(value, dict) and all(isinstance(k, str) and kind(v) for k, v in value.items())


def _is(*types: type) -> Callable[[Any], bool]:
    return lambda value: isinstance(value, types) and not isinstance(value, bool)


def _anything(value: Any) -> bool:
    return True


# Field annotation (a string, as `from __future__ import annotations` leaves it) -> JSON shape check and its
# name in messages. Every annotation of the manifest's dataclasses is here: a manifest that parses has the
# types the runtime and `hrlsac policy info` use, whatever the file says (a damaged or hand-edited manifest
# must be refused, not crash the reader).
_SHAPES: dict[str, tuple[Callable[[Any], bool], str]] = {
    "int": (_is(int), "an integer"),
    "float": (_is_number, "a number"),
    "str": (_is(str), "a string"),
    "int | None": (lambda value: value is None or _is(int)(value), "an integer or null"),
    "tuple[str, ...]": (_is_list_of(_is(str)), "a list of strings"),
    "tuple[float, ...]": (_is_list_of(_is_number), "a list of numbers"),
    "tuple[dict, ...]": (_is_list_of(_is(dict)), "a list of objects"),
    "tuple[GoalSpec, ...]": (_is(list), "a list"),
    "dict[str, str]": (_is_dict_of(_is(str)), "an object of strings"),
    "dict[str, Any]": (_is_dict_of(_anything), "an object"),
    "dict[str, Any] | str": (lambda value: _is(str)(value) or _is_dict_of(_is(dict))(value),
                             "an object of objects (split -> metrics) or a string"),
    "ObservationSpec": (_is(dict), "an object"),
    "ActionSpec": (_is(dict), "an object"),
    "SourceCheckpoint": (_is(dict), "an object"),
}
_NESTED = {"observation": ObservationSpec, "action": ActionSpec, "source_checkpoint": SourceCheckpoint}


def _build(cls: type, data: Any, where: str):
    """``cls`` from a JSON object: types checked, nested dataclasses rebuilt, lists as tuples, unknown keys
    ignored. A ValueError names the first field that is missing or of the wrong type."""
    if not isinstance(data, dict):
        raise ValueError(f"{where} is not a JSON object")
    values = {}
    for field in dataclasses.fields(cls):
        if field.name not in data and field.default is not dataclasses.MISSING:
            continue  # added after the first version of the format: older manifests read as the default
        if field.name not in data:
            raise ValueError(f"{where} is missing the field {field.name!r}")
        value = data[field.name]
        check, expected = _SHAPES[field.type]
        if not check(value):
            raise ValueError(f"{where}.{field.name} must be {expected}, got {_brief_json(value)}")
        if field.name in _NESTED:
            value = _build(_NESTED[field.name], value, f"{where}.{field.name}")
        elif field.name == "goals":
            value = tuple(_build(GoalSpec, goal, f"{where}.goals[{i}]") for i, goal in enumerate(value))
        elif isinstance(value, list):
            value = tuple(value)
        values[field.name] = value
    if cls is ActionSpec and len({len(values[name]) for name in ("names", "low", "high", "units")}) != 1:
        raise ValueError(f"{where}: names, low, high and units must have the same length")
    if cls is ObservationSpec:
        for i, item in enumerate(values["fields"]):
            _build(_ObservationField, item, f"{where}.fields[{i}]")
    return cls(**values)


@dataclass(frozen=True)
class _ObservationField:
    """The shape of one entry of ``ObservationSpec.fields`` (checked on reading; the entries stay dicts)."""

    name: str
    offset: int
    size: int
    description: str


def _brief_json(value: Any, limit: int = 60) -> str:
    text = json.dumps(value)
    return text if len(text) <= limit else f"{text[:limit - 3]}..."


def summary_lines(manifest: PolicyManifest) -> list[str]:
    """A short human summary (``hrlsac export`` prints it, ``hrlsac policy info`` starts with it)."""
    config, source = manifest.training_config, manifest.source_checkpoint
    trainer = config.get("trainer") or f"{config.get('preset')} preset"  # another library's, or hrlsac's preset
    hierarchy = (f"K = {manifest.subgoal_interval}, goals {', '.join(g.name for g in manifest.goals)}"
                 if manifest.hierarchical else "flat (no meta-controller)")
    actions = ", ".join(f"{name} [{low:g}, {high:g}]" for name, low, high
                        in zip(manifest.action.names, manifest.action.low, manifest.action.high))
    precision = ("" if manifest.precision == "float32" else
                 f", {manifest.precision} (actions within {manifest.action_tolerance:g} of the trained policy)")
    return [
        f"{manifest.algorithm} policy, {manifest.format} (artifact format {manifest.format_version}{precision}): "
        f"{hierarchy}",
        f"  trained: {trainer}, seed {config.get('seed')}, {source.trained_steps:,} steps; "
        f"from {source.file} (sha256 {source.sha256[:16]}...)",
        f"  observation: layout version {manifest.observation.layout_version}, {manifest.observation.dim} values "
        f"(meta-controller {manifest.observation.meta_dim}); actions: {actions}",
        f"  evaluation: {evaluation_summary(manifest.evaluation)}",
        f"  exported {manifest.created_at} with torch {manifest.torch_version}",
    ]


def evaluation_summary(evaluation: dict[str, Any] | str) -> str:
    """One line per manifest: success, reward and coverage of each evaluated split, or "not evaluated"."""
    if not isinstance(evaluation, dict) or not evaluation:
        return NOT_EVALUATED
    def number(metrics: dict, key: str, spec: str) -> str:  # a missing or non-numeric metric shows as n/a
        value = metrics.get(key) if isinstance(metrics, dict) else None
        return format(value, spec) if _is_number(value) else "n/a"

    return "; ".join(f"{split} ({number(m, 'episodes', 'g')} episodes): success {number(m, 'success_rate', '.1%')}, "
                     f"reward {number(m, 'reward_mean', '.1f')}, coverage {number(m, 'coverage_mean', '.1%')}"
                     for split, m in evaluation.items())
