"""Corrupt policy artifacts and checkpoints never crash: one PolicyArtifactError / ValueError line, exit code 2.

The artifact under test is exported here from an untrained small policy (the file format, not the weights, is
what matters), so the tests follow the current observation layout. Property-based cases (hypothesis,
derandomised) truncate it, flip its bytes, replace it with random bytes, and break its manifest one field at a
time; fixed cases cover the other files people pass by mistake. Every artifact that does load must also be
printable by ``hrlsac policy info``.
"""
from __future__ import annotations

import io
import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import torch
from cli_harness import assert_clean_error, run_cli
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from autonomy.artifact_seal import seal
from autonomy.policy import PolicyArtifactError, load_policy
from autonomy.policy_cli import info_lines
from autonomy.policy_manifest import MANIFEST_FILE
from autonomy.torch_compat import torchscript_calls
from missions.mission import FlightSettings
from missions.mission_file import LIBRARY_DIR
from policies.checkpoint import CheckpointPolicy
from policies.config import NetworkConfig, TrainConfig
from policies.export.artifact import artifact_bytes, build_manifest
from policies.export.module import policy_module

NET = NetworkConfig(hidden=(16, 16), head=8, dropout=0.1)
FUZZ = settings(derandomize=True, deadline=None, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


@pytest.fixture(scope="module")
def policy() -> CheckpointPolicy:
    config = TrainConfig.from_preset("default", algo="hrl-sac", seed=1, actor=NET, critic=NET, meta_actor=NET,
                                     meta_critic=NET, flight=FlightSettings(subgoal_interval=10))
    return CheckpointPolicy.untrained(config)


@pytest.fixture(scope="module")
def scripted(policy):
    """The TorchScript program, scripted once; saved with any manifest text by :func:`with_manifest`."""
    with torchscript_calls():
        return torch.jit.script(policy_module(policy))


@pytest.fixture(scope="module")
def manifest_data(policy) -> dict:
    return json.loads(build_manifest(policy, "torchscript", "0" * 64).to_json())


@dataclass(frozen=True)
class Artifact:
    """An intact artifact's bytes (kept out of repr: hypothesis prints its arguments when a case fails)."""

    data: bytes = field(repr=False)


@pytest.fixture(scope="module")
def artifact(policy, tmp_path_factory) -> Artifact:
    data = artifact_bytes(policy_module(policy), build_manifest(policy, "torchscript", "0" * 64))
    path = tmp_path_factory.mktemp("artifact") / "policy.pt"
    path.write_bytes(data)
    load_policy(path)  # the intact artifact loads: every refusal below is the damage's doing
    return Artifact(data)


def with_manifest(scripted, text: str | bytes) -> bytes:
    """An artifact of the real program with ``text`` as its manifest.json, sealed as ``hrlsac export`` does."""
    buffer = io.BytesIO()
    with torchscript_calls():
        torch.jit.save(scripted, buffer, _extra_files={MANIFEST_FILE: text})
    return seal(buffer.getvalue())


def outcome(path: Path) -> str:
    """"loaded" or the one-line PolicyArtifactError; any other exception fails the test."""
    try:
        policy = load_policy(path)
    except PolicyArtifactError as error:
        message = str(error)
        assert "\n" not in message and message.startswith(f"{path}: "), message
        return message
    assert info_lines(policy)  # what policy info prints must not fail on whatever the manifest says
    return "loaded"


# ---------------------------------------------------------------------------------------------- damaged bytes

@settings(FUZZ, max_examples=100)
@given(data=st.data())
def test_truncated_artifacts_are_refused(tmp_path, artifact, data):
    length = data.draw(st.integers(0, len(artifact.data) - 1), label="length")
    path = tmp_path / "policy.pt"
    path.write_bytes(artifact.data[:length])
    assert outcome(path) != "loaded"


@settings(FUZZ, max_examples=60)
@given(data=st.data())
def test_flipped_bytes_are_refused(tmp_path, artifact, data):
    # Anywhere: in a member's data, a header, the padding between members (which no CRC-32 covers), the seal.
    damaged = bytearray(artifact.data)
    for position in data.draw(st.lists(st.integers(0, len(damaged) - 1), min_size=1, max_size=4, unique=True),
                              label="at"):
        damaged[position] ^= data.draw(st.integers(1, 255), label="xor")
    path = tmp_path / "policy.pt"
    path.write_bytes(bytes(damaged))
    message = outcome(path)
    assert "corrupt file" in message or "truncated or damaged file" in message or "not a policy artifact" in message


def test_every_byte_is_covered_by_the_seal(tmp_path, artifact):
    # Every 16th byte flipped in turn, so that every zip structure is hit: local headers, their padding, the
    # central directory, the end record, the seal itself. CRC-32s alone missed flips in padding.
    path = tmp_path / "policy.pt"
    for position in range(0, len(artifact.data), 16):
        damaged = bytearray(artifact.data)
        damaged[position] ^= 0x20
        path.write_bytes(bytes(damaged))
        assert outcome(path) != "loaded", f"a flip at byte {position} of {len(damaged)} went unnoticed"


def test_an_unsealed_artifact_is_refused(tmp_path, scripted, manifest_data):
    buffer = io.BytesIO()
    with torchscript_calls():
        torch.jit.save(scripted, buffer, _extra_files={MANIFEST_FILE: json.dumps(manifest_data)})
    path = tmp_path / "policy.pt"
    path.write_bytes(buffer.getvalue())
    message = outcome(path)
    assert "no seal at the end of the file" in message and "export it again" in message
    path.write_bytes(seal(buffer.getvalue()))
    assert outcome(path) == "loaded"


@settings(FUZZ, max_examples=100)
@given(content=st.binary(max_size=2000), zip_magic=st.booleans())
def test_random_bytes_are_refused(tmp_path, content, zip_magic):
    path = tmp_path / "policy.pt"
    path.write_bytes((b"PK\x03\x04" if zip_magic else b"") + content)
    assert outcome(path) != "loaded"


# ---------------------------------------------------------------------------------------------- broken manifest

def manifest_paths(value: Any, path: tuple = ()) -> list[tuple]:
    """Key paths of every node of the manifest JSON (the observation's 300 field descriptions sampled)."""
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    paths = []
    for key, item in items:
        if isinstance(key, int) and key > 1:  # the first two entries of a list stand for the rest
            continue
        paths += [(*path, key), *manifest_paths(item, (*path, key))]
    return paths


JSON_VALUES = st.recursive(st.none() | st.booleans() | st.integers(-10**6, 10**6) | st.floats(allow_nan=False)
                           | st.text(max_size=8),
                           lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=5), inner,
                                                                                       max_size=3), max_leaves=8)


@settings(FUZZ, max_examples=150)
@given(data=st.data(), delete=st.booleans())
def test_a_broken_manifest_field_is_refused_or_harmless(tmp_path, scripted, manifest_data, data, delete):
    document = json.loads(json.dumps(manifest_data))
    path_in_json = data.draw(st.sampled_from(manifest_paths(document)), label="field")
    container = document
    for key in path_in_json[:-1]:
        container = container[key]
    if delete:
        del container[path_in_json[-1]]
    else:
        container[path_in_json[-1]] = data.draw(JSON_VALUES, label="value")
    path = tmp_path / "policy.pt"
    path.write_bytes(with_manifest(scripted, json.dumps(document)))
    # Refused with one line, or (a description, the provenance) loads and prints.
    event("loads" if outcome(path) == "loaded" else "clean error")


@settings(FUZZ, max_examples=60)
@given(text=st.binary(max_size=200) | st.text(max_size=200).map(str.encode))
def test_a_manifest_that_is_not_json_is_refused(tmp_path, scripted, text):
    path = tmp_path / "policy.pt"
    path.write_bytes(with_manifest(scripted, text))
    message = outcome(path)
    assert message != "loaded" and "manifest" in message


@pytest.mark.parametrize("change, message", [
    ({"format_version": 2}, "unknown artifact format version 2"),
    ({"observation": {"dim": 100}}, "observation layout of the artifact does not match this runtime's (dim 100 vs"),
    ({"observation": {"layout_version": 0}}, "(layout_version 0 vs"),
    ({"observation": {"fields": 3}}, "manifest.observation.fields must be a list of objects, got 3"),
    ({"observation": {"fields": [{"name": "agent_position"}]}},
     "manifest.observation.fields[0] is missing the field 'offset'"),
    ({"action": {"names": 5}}, "manifest.action.names must be a list of strings, got 5"),
    ({"action": {"low": ["a", "b", "c", "d"]}}, "manifest.action.low must be a list of numbers"),
    ({"action": {"low": [-1]}}, "manifest.action: names, low, high and units must have the same length"),
    ({"goals": None}, "manifest.goals must be a list, got null"),
    ({"goals": [{"index": 0, "name": "Explore", "grounding": "x"}]}, "goals of the artifact ('Explore',) do not match"),
    ({"subgoal_interval": 0}, "manifest subgoal_interval must be at least 1, got 0"),
    ({"training_config": [1]}, "manifest.training_config must be an object, got [1]"),
    ({"evaluation": {"test": 5}}, "manifest.evaluation must be an object of objects"),
    ({"entry_points": {"act": 1}}, "manifest.entry_points must be an object of strings"),
    ({"source_checkpoint": {"trained_steps": "x"}}, "manifest.source_checkpoint.trained_steps must be an integer"),
    ({"format": "onnx"}, "manifest format 'onnx' is not one of torchscript, torch-export"),
    ({"format": "torch-export"}, "the torch-export program does not load"),
])
def test_manifest_problems_are_named(tmp_path, scripted, manifest_data, change, message):
    document = json.loads(json.dumps(manifest_data))
    for key, value in change.items():
        if isinstance(value, dict) and isinstance(document[key], dict):  # change some entries of a record
            document[key].update(value)
        else:
            document[key] = value
    path = tmp_path / "policy.pt"
    path.write_bytes(with_manifest(scripted, json.dumps(document)))
    assert message in outcome(path)


def test_odd_evaluation_metrics_still_print(tmp_path, scripted, manifest_data):
    document = dict(manifest_data, evaluation={"test": {"episodes": 2.5, "success_rate": "high"}})
    path = tmp_path / "policy.pt"
    path.write_bytes(with_manifest(scripted, json.dumps(document)))
    assert outcome(path) == "loaded"
    result = run_cli("policy", "info", str(path))
    assert result.code == 0 and "test (2.5 episodes): success n/a, reward n/a, coverage n/a" in result.out


# ---------------------------------------------------------------------------------------------- other files

def test_other_files_passed_as_an_artifact(tmp_path, scripted, manifest_data):
    other = tmp_path / "other_model.pt"
    with torchscript_calls():
        linear = torch.jit.script(torch.nn.Linear(3, 2))
        torch.jit.save(linear, str(other), _extra_files={MANIFEST_FILE: json.dumps(manifest_data)})
    other.write_bytes(seal(other.read_bytes()))  # sealed: only its program is wrong
    plain = tmp_path / "plain.pt"
    with torchscript_calls():
        torch.jit.save(linear, str(plain))
    checkpoint = tmp_path / "checkpoint.pt"
    torch.save({"config": {}, "normalizer": {}, "low": {}, "step": 0}, checkpoint)
    empty = tmp_path / "empty.pt"
    empty.write_bytes(b"")
    zipped_text = tmp_path / "notes.zip"
    with zipfile.ZipFile(zipped_text, "w") as archive:
        archive.writestr("notes.txt", "hello")
    cases = {
        other: "the torchscript program does not load (AttributeError",
        plain: "not a policy artifact (no manifest.json inside; a plain TorchScript file, "
               "not written by 'hrlsac export')",
        checkpoint: "a torch.save file, e.g. a training checkpoint: write its policy with 'hrlsac export CHECKPOINT",
        empty: "not a policy artifact (not a zip archive",
        zipped_text: "not a policy artifact (no manifest.json inside",
        tmp_path: "cannot read the file (Is a directory)",
        tmp_path / "missing.pt": "no such file",
        Path("/dev/zero"): "not a regular file",
    }
    for path, message in cases.items():
        assert message in outcome(path), path


# ---------------------------------------------------------------------------------------------- the commands

def test_policy_commands_exit_2_with_one_line(tmp_path, artifact):
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(artifact.data[: len(artifact.data) // 3])
    mission = str(LIBRARY_DIR / "demo.yaml")
    assert_clean_error(run_cli("policy", "info", str(truncated)), str(truncated), "truncated or damaged file")
    assert_clean_error(run_cli("policy", "info", str(truncated), "--json"), "truncated or damaged file")
    assert_clean_error(run_cli("mission", "replay", mission, "--policy", str(truncated), "--out", str(tmp_path)),
                       "hrlsac mission replay: error:", "truncated or damaged file")
    assert_clean_error(run_cli("mission", "run", mission, "--policy", str(truncated), "--connect", "udpin:x:1"),
                       "hrlsac mission run: error:", "truncated or damaged file")


def test_corrupt_checkpoints_exit_2_from_export_and_evaluate(tmp_path, artifact):
    files = {"random.pt": bytes(range(256)) * 4, "empty.pt": b"", "artifact.pt": artifact.data,
             "truncated.pt": artifact.data[:1000]}
    dict_file = tmp_path / "dict.pt"
    torch.save({"step": 3}, dict_file)
    for name, content in files.items():
        (tmp_path / name).write_bytes(content)
    for path in [*(tmp_path / name for name in files), dict_file]:
        for command in (["export", str(path), "-o", str(tmp_path / "out.pt")],
                        ["evaluate", str(path), "--episodes", "1", "--out", str(tmp_path / "eval.json")]):
            result = run_cli(*command)
            assert_clean_error(result, str(path), "not a readable training checkpoint")
            assert "\n" not in result.err.strip()
    assert not (tmp_path / "out.pt").exists() and not (tmp_path / "eval.json").exists()
    result = run_cli("export", str(tmp_path / "artifact.pt"), "-o", str(tmp_path / "out.pt"))
    assert "it is a policy artifact ('hrlsac policy info' reads it); give the training checkpoint" in result.err
    assert "no 'config', 'normalizer', 'low' in it" in run_cli("export", str(dict_file), "-o", "x.pt").err


def test_resume_from_a_corrupt_checkpoint_or_config_exits_2(tmp_path, policy):
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.json").write_text(json.dumps(policy.config.to_dict()))
    (run / "checkpoint.pt").write_bytes(b"PK\x03\x04 not really")
    result = run_cli("train", "--out", str(run), "--resume", "--quiet")
    assert_clean_error(result, f"{run / 'checkpoint.pt'}: not a readable training checkpoint")
    for config, problem in (("{bad", "JSONDecodeError"), ("[1]", "TypeError"), ("{}", "KeyError: 'flight'")):
        (run / "config.json").write_text(config)
        result = run_cli("train", "--out", str(run), "--resume", "--quiet")
        assert_clean_error(result, f"{run / 'config.json'}: not a readable training config ({problem}")
