"""The on-board policy runtime: load an exported artifact, check it, and run its two entry points.

A companion computer has the artifact and this package, not the training code: nothing here imports
``policies`` (or gymnasium); tests/test_export_parity.py loads and runs an artifact with ``policies`` hidden.

Before any weight is loaded, :func:`load_policy` checks the file (a zip archive, complete, its SHA-256 seal
intact: ``autonomy.artifact_seal``) and its manifest (a format version this runtime knows, the same observation
layout as ``autonomy.observation``, the same goals as ``missions.goals``). Whatever is wrong is raised as one
:class:`PolicyArtifactError` whose message is one line naming the file and the problem: flying a policy that
reads a different observation than the one it is given would fail silently, so a mismatch is refused.

The hierarchy as the runner needs it: every step ``act(obs)``; every K-th step (``goal_due(step)``, which asks
``missions.goals.goal_due``) first ``select_goal(meta_obs)``, then the runner grounds the goal to a point
(``missions.goals``), rebuilds the observation and acts on it. Both are deterministic (the mode of each policy).

Denormal floats: both calls run their program with the CPU's flush-to-zero / denormals-are-zero mode on
(``torch.set_flush_denormal``), as real-time inference code does, and turn it off again after it (so the caller's
own numpy and torch arithmetic, the belief search's tiny probabilities included, is not changed; a caller that had
turned it on itself finds it off). Observations carry denormal values (tiny belief probabilities), and on x86 every
multiply with one takes a microcode assist, which makes the slowest decision steps several times slower
(docs/export.md, "Latency"). A denormal is below any difference the networks resolve, so the
actions are those of the trained networks (tests/test_export_parity.py).
"""
from __future__ import annotations

import hashlib
import io
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from autonomy.artifact_seal import SealError, ends_with_zip_end, is_sealed, unseal
from autonomy.observation import GOAL_NAMES, META_OBS_DIM, OBS_DIM
from autonomy.policy_manifest import MANIFEST_FILE, ObservationSpec, PolicyManifest
from autonomy.torch_compat import pt2_archive, torchscript_calls
from missions.action_frames import ActionFrame
from missions.goals import goal_due
from missions.search_state_v1 import BeliefSearchState

ZIP_MAGIC = b"PK\x03\x04"
# Names of the two programs in a torch-export artifact (a PT2 archive). "model" is the name plain
# torch.export.load reads, so that call alone gives the every-step program.
ACT_PROGRAM = "model"
GOAL_PROGRAM = "select_goal"

Program = Callable[[torch.Tensor], torch.Tensor]


class PolicyArtifactError(ValueError):
    """A policy artifact that cannot be flown; the message is one line: the file, then the problem."""


@dataclass
class Policy:
    """A loaded, checked artifact: ``act`` every step, ``select_goal`` when a goal is due (every ``subgoal_interval``
    steps)."""

    manifest: PolicyManifest
    path: Path
    sha256: str
    """Of the artifact file: names exactly what was flown (mission reports, flight logs)."""
    _act: Program
    _select_goal: Program

    @property
    def hierarchical(self) -> bool:
        return self.manifest.hierarchical

    @property
    def subgoal_interval(self) -> int | None:
        """K: steps between goal decisions (None for a flat policy)."""
        return self.manifest.subgoal_interval

    @property
    def action_frame(self) -> ActionFrame:
        """How its movement is read (``missions.action_frames.ActionFrame``): as trained, north / east unless the
        training said otherwise."""
        return ActionFrame(self.manifest.training_config.get("action_frame", ActionFrame.NORTH_EAST))

    def goal_due(self, step: int) -> bool:
        """Whether the meta-controller decides at this step of a mission by the clock alone
        (``missions.goals.goal_due``: steps 0, K, 2K, ... since the last decision); never for a flat policy. For
        loops of your own (docs/export.md). On SarSearch-v1 the flight pilot also decides at once after a decision
        event (a new candidate, the bingo call), which its search state tells:
        ``missions.search_state_v1.BeliefSearchState.goal_due``."""
        return self.hierarchical and bool(goal_due(step, self.manifest.subgoal_interval))

    def attach(self, state: BeliefSearchState) -> None:
        """Nothing to do: an artifact acts on the observation alone (``autonomy.search_pilot.FlownPolicy``)."""

    def describe(self) -> dict:
        """The report's account of the pilot: the artifact's algorithm, path and SHA-256."""
        return {"pilot": self.manifest.algorithm, "policy": str(self.path), "policy_sha256": self.sha256}

    def select_goal(self, meta_obs: np.ndarray) -> np.ndarray:
        """(N, 284) or (284,) raw meta observations -> goal indices (N,) or a scalar, int64 (-1: flat policy)."""
        return self._run(self._select_goal, meta_obs, META_OBS_DIM)

    def act(self, obs: np.ndarray) -> np.ndarray:
        """(N, 288) or (288,) raw observations -> actions (N, 4) or (4,), float32, in the action ranges."""
        return self._run(self._act, obs, OBS_DIM)

    @staticmethod
    def _run(program: Program, values: np.ndarray, width: int) -> np.ndarray:
        # float32 is what the observation builder makes and what the programs take.
        batch = np.ascontiguousarray(values, dtype=np.float32)
        single = batch.ndim == 1
        if single:
            batch = batch[None, :]
        if batch.ndim != 2 or batch.shape[1] != width:
            raise ValueError(f"expected observations of shape (N, {width}) or ({width},), got {np.shape(values)}")
        torch.set_flush_denormal(True)  # see the module docstring (a register write each way)
        try:
            with torch.inference_mode():
                out = program(torch.from_numpy(batch)).numpy()
        finally:
            torch.set_flush_denormal(False)
        return out[0] if single else out


def load_policy(path: Path | str) -> Policy:
    """Read, check and load an artifact written by ``hrlsac export``; raises :class:`PolicyArtifactError`."""
    path = Path(path)
    try:
        if path.exists() and not (path.is_file() or path.is_dir()):  # a FIFO or /dev/zero would never end
            raise PolicyArtifactError(f"{path}: not a regular file (a device, FIFO or socket?)")
        data = path.read_bytes()
    except FileNotFoundError:
        raise PolicyArtifactError(f"{path}: no such file") from None
    except OSError as exc:
        raise PolicyArtifactError(f"{path}: cannot read the file ({exc.strerror})") from None
    manifest, archive = read_manifest(data, str(path))
    check_compatible(manifest, str(path))
    try:
        act, select_goal = _LOADERS[manifest.format](archive)
    except Exception as exc:  # torch raises anything from RuntimeError to pickle errors for a bad program
        raise PolicyArtifactError(f"{path}: the {manifest.format} program does not load "
                                  f"({one_line(exc)})") from None
    policy = Policy(manifest, path, hashlib.sha256(data).hexdigest(), act, select_goal)
    _self_test(policy, str(path))
    return policy


def one_line(exc: BaseException) -> str:
    """An exception as "Type: first line of its message" (torch's messages run over many lines)."""
    lines = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {lines[0]}" if lines else type(exc).__name__


def read_manifest(data: bytes, name: str) -> tuple[PolicyManifest, bytes]:
    """The manifest of an artifact's bytes and the archive as torch wrote it, after checking its seal."""
    if not data.startswith(ZIP_MAGIC):
        raise PolicyArtifactError(f"{name}: not a policy artifact (not a zip archive; expected a file written "
                                  "by 'hrlsac export')")
    if is_sealed(data):
        try:
            archive = unseal(data)
        except SealError as exc:
            raise PolicyArtifactError(f"{name}: corrupt file ({exc}; copy the artifact again)") from None
    elif ends_with_zip_end(data):
        archive = None  # a zip as torch writes it: not ours, or damaged where the seal was; told apart below
    else:
        # Checked here rather than left to zipfile: where the end record is not last, zipfile would search back
        # and may find the end record of an archive nested inside (a PT2 archive holds torch.save files).
        raise PolicyArtifactError(f"{name}: truncated or damaged file (no zip end record at the end; copy the "
                                  "artifact again)")
    try:
        zip_file = zipfile.ZipFile(io.BytesIO(archive or data))
        members = zip_file.namelist()
    except Exception as exc:  # BadZipFile, but a damaged directory also gives UnicodeDecodeError, struct.error, ...
        raise PolicyArtifactError(f"{name}: truncated or damaged file (its zip directory is unreadable: "
                                  f"{one_line(exc)}; copy the artifact again)") from None
    manifests = [m for m in members if m.split("/")[-2:] == ["extra", MANIFEST_FILE]]
    if len(manifests) != 1:
        raise PolicyArtifactError(f"{name}: not a policy artifact (no {MANIFEST_FILE} inside; "
                                  f"{_what_archive(members)})")
    if archive is None:
        raise PolicyArtifactError(f"{name}: no seal at the end of the file (damaged there, or exported before "
                                  "'hrlsac export' sealed its artifacts; export it again)")
    try:
        text = zip_file.read(manifests[0])
        return PolicyManifest.from_json(text), archive
    except (ValueError, TypeError) as exc:
        raise PolicyArtifactError(f"{name}: {exc}") from None


def _what_archive(members: list[str]) -> str:
    """A guess at what a zip without a manifest is, with what to do about it."""
    if any("/code/" in m or m.endswith("/constants.pkl") for m in members):
        return "a plain TorchScript file, not written by 'hrlsac export'"
    if any(m.endswith("/data.pkl") for m in members):
        return ("a torch.save file, e.g. a training checkpoint: write its policy with "
                "'hrlsac export CHECKPOINT -o policy.pt'")
    return "a plain TorchScript or torch.export file?"


def check_compatible(manifest: PolicyManifest, name: str) -> None:
    """Refuse an artifact trained on another observation layout or with other goals than this runtime's."""
    try:
        difference = manifest.observation.difference(ObservationSpec.current())
    except (KeyError, TypeError):
        difference = "the artifact's field list is malformed"
    if difference is not None:
        raise PolicyArtifactError(f"{name}: observation layout of the artifact does not match this runtime's "
                                  f"({difference}); export the policy again or use a matching runtime")
    names = tuple(goal.name for goal in manifest.goals)
    if manifest.hierarchical and names != GOAL_NAMES:
        raise PolicyArtifactError(f"{name}: goals of the artifact {names} do not match this runtime's "
                                  f"{GOAL_NAMES}")
    if len(manifest.action.names) != 4:
        raise PolicyArtifactError(f"{name}: the artifact has {len(manifest.action.names)} actions, this "
                                  "runtime flies 4")


def _load_torchscript(data: bytes) -> tuple[Program, Program]:
    with torchscript_calls():
        module = torch.jit.load(io.BytesIO(data), map_location="cpu")
    return module.act, module.select_goal


def _load_torch_export(data: bytes) -> tuple[Program, Program]:
    programs = pt2_archive().load_pt2(io.BytesIO(data)).exported_programs
    return programs[ACT_PROGRAM].module(), programs[GOAL_PROGRAM].module()


_LOADERS = {"torchscript": _load_torchscript, "torch-export": _load_torch_export}


def _self_test(policy: Policy, name: str) -> None:
    """One call of each entry point on a zero observation: the programs must answer in the declared shapes."""
    try:
        action = policy.act(np.zeros((1, OBS_DIM), dtype=np.float32))
        goal = policy.select_goal(np.zeros((1, META_OBS_DIM), dtype=np.float32))
    except Exception as exc:  # whatever the program raises, the artifact cannot be flown
        raise PolicyArtifactError(f"{name}: the program fails on a zero observation ({one_line(exc)})") from None
    if action.shape != (1, 4) or action.dtype != np.float32:
        raise PolicyArtifactError(f"{name}: act returned {action.dtype} {action.shape}, expected float32 (1, 4)")
    if goal.shape != (1,) or goal.dtype != np.int64:
        raise PolicyArtifactError(f"{name}: select_goal returned {goal.dtype} {goal.shape}, expected int64 (1,)")
