"""Export a training checkpoint to one self-describing policy artifact (``hrlsac export``).

The artifact is a zip archive holding the deterministic policy (:mod:`policies.export.module`) and its
manifest (:mod:`autonomy.policy_manifest`) as ``manifest.json``, in one of two formats (docs/export.md):

* ``torchscript``: ``torch.jit.save`` of the scripted ``PolicyModule`` (methods ``act``, ``select_goal``),
  the manifest as a TorchScript extra file. Loads with plain ``torch.jit.load``, or libtorch in C++.
* ``torch-export``: a PT2 archive with two ``ExportedProgram`` s, ``"model"`` (act) and ``"select_goal"``,
  the manifest as an extra file of the archive. ``torch.export.load`` alone gives the act program.

The artifact is written to a temporary file and renamed into place, after the optional parity check
(:mod:`policies.export.parity`): a failed or interrupted export never leaves a partial or unchecked file.
"""
from __future__ import annotations

import hashlib
import inspect
import io
import json
import os
import re
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

import torch

from autonomy.artifact_seal import seal
from autonomy.observation import META_OBS_DIM, OBS_DIM
from autonomy.policy import ACT_PROGRAM, GOAL_PROGRAM, Policy, load_policy
from autonomy.policy_manifest import (
    FORMAT_VERSION,
    MANIFEST_FILE,
    NOT_EVALUATED,
    ActionSpec,
    GoalSpec,
    ObservationSpec,
    PolicyManifest,
    SourceCheckpoint,
)
from autonomy.torch_compat import pt2_archive, torchscript_calls
from missions import goals as goal_logic
from missions.action_frames import ARRIVAL_STEPS
from missions.search import SENSOR_ON_INTENSITY, ZOOM_RANGE
from policies.checkpoint import CheckpointPolicy, checkpoint_file
from policies.env.core import ACTION_HIGH, ACTION_LOW, ACTION_NAMES
from policies.export.module import PRECISIONS, PolicyModule, policy_module
from policies.export.parity import TOLERANCES, Parity, check_parity, record_observations

ACTION_UNITS = (
    "fraction of flight.max_speed_mps: velocity north (m/s) = value * max_speed_mps",
    "fraction of flight.max_speed_mps: velocity east (m/s) = value * max_speed_mps",
    f"sensor effort, 1 = full: detection probability scales with it, coverage counts from {SENSOR_ON_INTENSITY}",
    f"zoom, 1 = full: camera footprint half-width = altitude * tan(FOV / 2) / (1 + {ZOOM_RANGE:g} * zoom)",
)
TARGET_FRAME_NAMES = ("movement_towards_target", "movement_right_of_target") + ACTION_NAMES[2:]
TARGET_FRAME_UNITS = (
    "fraction of flight.max_speed_mps towards the observation's target point (target_offset's direction)",
    "fraction of flight.max_speed_mps to the right of the line to the target (90 degrees clockwise from it)",
) + ACTION_UNITS[2:]
"""The action spec of a policy trained with ``action_frame`` "target" (SarSearch-v1)."""
ARRIVE_FRAME_UNITS = tuple(
    unit.replace("fraction of flight.max_speed_mps", "fraction of min(flight.max_speed_mps, distance to the target / "
                 f"({ARRIVAL_STEPS:g} * flight.step_period_s))") for unit in TARGET_FRAME_UNITS[:2]) + ACTION_UNITS[2:]
"""The action spec of a policy trained with ``action_frame`` "arrive" (SarSearch-v1): as "target", with the speed
also capped by what covers the rest of the way to the target in ``ARRIVAL_STEPS`` steps
(``missions.action_frames.arrival_speed_fraction``)."""
FRAME_SPECS = {"north_east": (ACTION_NAMES, ACTION_UNITS), "target": (TARGET_FRAME_NAMES, TARGET_FRAME_UNITS),
               "arrive": (TARGET_FRAME_NAMES, ARRIVE_FRAME_UNITS)}
ENTRY_POINTS = {
    "act": f"obs float32 [N, {OBS_DIM}] raw (observation layout) -> actions float32 [N, 4] within action low/high",
    "select_goal": f"obs float32 [N, {META_OBS_DIM}] raw (the first {META_OBS_DIM} values) -> goal indices int64 "
                   "[N] (-1: flat SAC, no meta-controller)",
}
EVALUATION_FILES = "eval_*.json"  # what ``hrlsac evaluate RUN`` writes into the run folder


class ParityError(RuntimeError):
    """The exported artifact does not reproduce the eager policy (nothing was written)."""


@dataclass
class ExportResult:
    """What ``export_policy`` wrote, for the command's summary."""

    path: Path
    manifest: PolicyManifest
    size_bytes: int
    parity: Parity | None = None
    notes: list[str] = field(default_factory=list)


def export_policy(checkpoint: Path | str, out: Path | str, fmt: str = "torchscript",
                  check: bool = False, precision: str = "float32") -> ExportResult:
    """Write the artifact of a checkpoint (file or run folder) to ``out``; ``check``: parity check first;
    ``precision``: "float32" (as trained) or "int8" (``policies.export.module``; docs/export.md, "Precision")."""
    out = checked_destination(out)
    policy, sha256 = read_checkpoint(checkpoint)
    evaluation, notes = evaluation_metrics(policy)
    manifest = build_manifest(policy, fmt, sha256, evaluation, precision)
    data = artifact_bytes(policy_module(policy, precision), manifest)

    def parity_of(artifact: Policy) -> Parity:
        parity = check_parity(policy, artifact, record_observations(policy))
        if not parity.ok:
            raise ParityError(f"parity check failed: {parity.summary()}; nothing written")
        return parity

    parity = write_artifact(out, data, parity_of if check else None)
    return ExportResult(out, manifest, len(data), parity, notes)


def checked_destination(out: Path | str) -> Path:
    """``out`` as a path, refused (ValueError) unless it names a file in an existing folder."""
    out = Path(out)
    if out.is_dir() or not out.parent.is_dir():
        raise ValueError(f"{out}: the artifact must be a file in an existing folder")
    return out


def write_artifact(out: Path, data: bytes, check: Callable[[Policy], Parity] | None = None) -> Parity | None:
    """Write the artifact ``data`` to ``out`` through a temporary file renamed into place; ``check`` is first handed
    the temporary file loaded by the runtime and may refuse it (``ParityError``): then nothing is written."""
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    parity = None
    try:
        tmp.write_bytes(data)
        if check is not None:
            parity = check(load_policy(tmp))
        os.replace(tmp, out)
    finally:
        tmp.unlink(missing_ok=True)
    return parity


def read_checkpoint(path: Path | str) -> tuple[CheckpointPolicy, str]:
    """The policy of a checkpoint and the SHA-256 of exactly the bytes it was loaded from (training may
    replace the file meanwhile: both come from one open handle)."""
    path = checkpoint_file(path)
    with path.open("rb") as handle:
        sha256 = hashlib.file_digest(handle, "sha256").hexdigest()
        handle.seek(0)
        policy = CheckpointPolicy.read(handle, path)
    return policy, sha256


def evaluation_metrics(policy: CheckpointPolicy) -> tuple[dict | str, list[str]]:
    """``hrlsac evaluate``'s metrics of this very checkpoint (evaluation -> metrics, without the per-episode lists),
    or "not evaluated"; plus notes on evaluation files that were left out (another checkpoint's, or a constant
    goal's, which does not evaluate the policy). An evaluation is named by its split, its scenarios when they are
    not the split's own generator scenarios, and ", flight rules" when flown with the mission runner's rules."""
    found, notes = {}, []
    for path in sorted(policy.path.parent.glob(EVALUATION_FILES)):
        try:
            metrics = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError):
            notes.append(f"left out {path.name}: not readable JSON")
            continue
        if not isinstance(metrics, dict):
            notes.append(f"left out {path.name}: not a metrics object")
            continue
        if metrics.get("trained_steps") != policy.step:
            notes.append(f"left out {path.name}: it evaluated step {metrics.get('trained_steps')}, "
                         f"the checkpoint is at step {policy.step}")
            continue
        if metrics.get("constant_goal") is not None:
            continue  # the learned low level under one goal: not this policy's evaluation
        name = str(metrics.get("split", path.stem))
        scenarios = str(metrics.get("scenarios", ""))
        if scenarios and not scenarios.startswith("generator split"):
            name += f" ({scenarios})"
        found[name + (", flight rules" if metrics.get("flight_rules") else "")] = {
            k: v for k, v in metrics.items() if k not in ("per_episode", "checkpoint")}
    return found or NOT_EVALUATED, notes


def goal_specs() -> tuple[GoalSpec, ...]:
    """Goal names with their grounding on SarSearch-v1, the task every exportable policy was trained on, as
    documented by ``missions.goals.ground_goals_v1`` (one bullet per goal)."""
    grounding = {}
    for bullet in re.split(r"\n\* ", inspect.cleandoc(goal_logic.ground_goals_v1.__doc__ or ""))[1:]:
        name, _, text = bullet.partition(":")
        grounding[name.strip()] = " ".join(text.split("\n\n")[0].split())
    return tuple(GoalSpec(i, name, grounding.get(name, "see missions/goals.py"))
                 for i, name in enumerate(goal_logic.GOAL_NAMES))


def build_manifest(policy: CheckpointPolicy, fmt: str, checkpoint_sha256: str,
                   evaluation: dict | str = NOT_EVALUATED, precision: str = "float32") -> PolicyManifest:
    """The manifest of ``policy`` exported in format ``fmt`` and ``precision``."""
    config = policy.config
    return flight_manifest(fmt, config.algo, config.action_frame, config.to_dict(),
                           SourceCheckpoint(policy.path.name, checkpoint_sha256, policy.step), evaluation, precision,
                           config.flight.subgoal_interval if policy.hierarchical else None)


def flight_manifest(fmt: str, algorithm: str, action_frame: str, training_config: dict, source: SourceCheckpoint,
                    evaluation: dict | str = NOT_EVALUATED, precision: str = "float32",
                    subgoal_interval: int | None = None) -> PolicyManifest:
    """The manifest of a policy of ``algorithm`` that acts in ``action_frame`` on this runtime's observation layout,
    exported from ``source`` in format ``fmt`` and ``precision``; hierarchical (goals, K) when ``subgoal_interval``
    is given. ``training_config`` is what the runner reads the policy's training settings from (``flight``,
    ``task``, ``action_frame``)."""
    if precision not in PRECISIONS:
        raise ValueError(f"unknown precision {precision!r} (choose {' or '.join(PRECISIONS)})")
    names, units = FRAME_SPECS[action_frame]
    return PolicyManifest(
        format_version=FORMAT_VERSION, format=fmt, algorithm=algorithm, subgoal_interval=subgoal_interval,
        goals=goal_specs() if subgoal_interval is not None else (),
        observation=ObservationSpec.current(),
        action=ActionSpec(names, tuple(ACTION_LOW.tolist()), tuple(ACTION_HIGH.tolist()), units),
        # Through JSON once, so that the manifest in memory equals the one read back (lists, not tuples).
        entry_points=ENTRY_POINTS, training_config=json.loads(json.dumps(training_config)), evaluation=evaluation,
        source_checkpoint=source, torch_version=torch.__version__,
        created_at=datetime.now(timezone.utc).isoformat(timespec="seconds"), precision=precision,
        action_tolerance=TOLERANCES[precision])


def artifact_bytes(module: PolicyModule, manifest: PolicyManifest) -> bytes:
    """The artifact of ``module`` in ``manifest.format``, with ``manifest`` inside, sealed (``artifact_seal``)."""
    extra = {MANIFEST_FILE: manifest.to_json()}
    buffer = io.BytesIO()
    if manifest.format == "torchscript":
        with torchscript_calls():
            torch.jit.save(torch.jit.script(module), buffer, _extra_files=extra)
    elif manifest.format == "torch-export":
        programs = {ACT_PROGRAM: exported_program(module.action_head, OBS_DIM),
                    GOAL_PROGRAM: exported_program(module.goal_head, META_OBS_DIM)}
        pt2_archive().package_pt2(buffer, exported_programs=programs, extra_files=extra)
    else:
        raise ValueError(f"unknown artifact format {manifest.format!r} (choose torchscript or torch-export)")
    return seal(buffer.getvalue())


def exported_program(head: torch.nn.Module, width: int) -> torch.export.ExportedProgram:
    """``head`` exported for float32 batches (N, width) of any N >= 1."""
    batch = torch.export.Dim("batch", min=1)
    return torch.export.export(head, (torch.zeros(2, width),), dynamic_shapes=({0: batch},))
