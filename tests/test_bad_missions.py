"""Malformed mission files never crash: every broken document is one MissionFileError line naming the field.

Property-based (hypothesis, derandomised: the same examples on every run): random bytes and text, random
YAML documents, and the bundled demo mission with one field broken at a time (a value of the wrong kind,
a non-finite or huge number, a missing key, an unknown key). Then the files that are not mission files at all,
and the same errors through ``hrlsac mission replay``.
"""
from __future__ import annotations

import copy
import math
import os
import subprocess
from pathlib import Path
from typing import Any

import pytest
import yaml
from cli_harness import HRLSAC, assert_clean_error, run_cli
from hypothesis import HealthCheck, assume, event, given, settings
from hypothesis import strategies as st

from missions.mission_file import LIBRARY_DIR, MissionFileError, load_mission

DEMO = LIBRARY_DIR / "demo.yaml"
DEMO_DATA = yaml.safe_load(DEMO.read_text())
POLICY = Path(__file__).resolve().parents[1] / "policies" / "pretrained" / "hrl-sac.pt"
RUNS = 200  # examples per property (each is a file load, a few ms)
# Derandomised: the same examples on every run. tmp_path is shared by a test's examples (each rewrites the file).
FUZZ = settings(max_examples=RUNS, derandomize=True, deadline=None, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])


def write(tmp_path: Path, content: str | bytes, name: str = "mission.yaml") -> Path:
    path = tmp_path / name
    path.write_bytes(content if isinstance(content, bytes) else content.encode("utf-8", "surrogatepass"))
    return path


def load_error(path: Path) -> MissionFileError | None:
    """The MissionFileError of loading ``path`` (None if it loads); any other exception fails the test."""
    try:
        load_mission(path)
    except MissionFileError as error:
        message = str(error)
        assert "\n" not in message and message.startswith(f"{path}: ") and error.reason, message
        return error
    return None


# ---------------------------------------------------------------------------------------------- random input

@FUZZ
@given(content=st.binary(max_size=400))
def test_random_bytes_are_a_clean_error(tmp_path, content):
    assert load_error(write(tmp_path, content)) is not None


@FUZZ
@given(content=st.text(max_size=300))
def test_random_text_is_a_clean_error(tmp_path, content):
    assert load_error(write(tmp_path, content)) is not None


MISSION_WORDS = ["name", "flight", "geofence", "scenario", "home", "area", "targets", "datum", "generator",
                 "dataset", "altitude_m", "lat_deg", "north_m", "seed", "split", "index", "root", "category"]
SCALARS = (st.none() | st.booleans() | st.integers(-10**30, 10**30) | st.floats(allow_nan=True)
           | st.text(max_size=12) | st.sampled_from(["test", "person", "calm", "1e3", "1.0e+400", "~", "yes"]))
DOCUMENTS = st.recursive(SCALARS, lambda inner: st.lists(inner, max_size=4)
                         | st.dictionaries(st.sampled_from(MISSION_WORDS) | st.text(max_size=6), inner, max_size=5),
                         max_leaves=25)


@FUZZ
@given(document=DOCUMENTS)
def test_random_yaml_documents_are_a_clean_error(tmp_path, document):
    # Almost never a valid mission; when one is, it loads (load_error returns None).
    error = load_error(write(tmp_path, yaml.safe_dump(document, allow_unicode=True)))
    event("loads" if error is None else "clean error")


# ---------------------------------------------------------------------------------------------- one broken field

def field_paths(value: Any, path: str = "") -> list[str]:
    """Dotted paths of every node below the top (``scenario.targets[0].category``), in the loader's spelling."""
    paths = []
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    for key, item in items:
        child = f"{path}[{key}]" if isinstance(value, list) else (f"{path}.{key}" if path else key)
        paths += [child, *field_paths(item, child)]
    return paths


DEMO_PATHS = field_paths(DEMO_DATA)


def locate(data: Any, path: str) -> tuple[Any, Any]:
    """(container, key) of the node at ``path`` in ``data``."""
    parts = path.replace("[", ".[").split(".")
    for part in parts[:-1]:
        data = data[int(part[1:-1])] if part.startswith("[") else data[part]
    last = parts[-1]
    return data, int(last[1:-1]) if last.startswith("[") else last


def parent_path(path: str) -> str:
    """``scenario.targets[0].category`` -> ``scenario.targets[0]`` -> ``scenario.targets``; ``name`` -> ``""``."""
    cut = max(path.rfind("."), path.rfind("["))
    return path[:cut] if cut > 0 else ""


def kind(value: Any) -> str:
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, (int, float)):
        return "number"
    return type(value).__name__


WRONG_KINDS = {
    "bool": st.booleans(),
    "number": st.integers(-10**6, 10**6) | st.floats(-1e6, 1e6),
    "str": st.text(min_size=1, max_size=10).filter(str.strip),
    "list": st.lists(st.integers(), max_size=3),
    "dict": st.dictionaries(st.sampled_from(["a", "north_m", "x"]), st.integers(), max_size=2),
    "bytes": st.binary(min_size=1, max_size=5),
}


@st.composite
def wrong_kind_value(draw, original: Any) -> Any:
    """A value of another kind than ``original`` (a number where a mapping belongs, a list where a string...)."""
    kinds = [k for k in WRONG_KINDS if k != kind(original)]
    return draw(WRONG_KINDS[draw(st.sampled_from(kinds))])


@FUZZ
@given(data=st.data(), path=st.sampled_from(DEMO_PATHS))
def test_a_value_of_the_wrong_kind_is_named_by_its_field_path(tmp_path, data, path):
    document = copy.deepcopy(DEMO_DATA)
    container, key = locate(document, path)
    container[key] = data.draw(wrong_kind_value(container[key]), label="value")
    error = load_error(write(tmp_path, yaml.safe_dump(document)))
    assert error is not None and error.field == path, (path, container[key], error)


def value_at(data: Any, path: str) -> Any:
    container, key = locate(data, path)
    return container[key]


NUMBER_PATHS = [path for path in DEMO_PATHS if kind(value_at(DEMO_DATA, path)) == "number"]
NON_FINITE = st.sampled_from([math.nan, math.inf, -math.inf, 10**400, -10**400, 10**4000])


@FUZZ
@given(path=st.sampled_from(NUMBER_PATHS), value=NON_FINITE)
def test_non_finite_and_huge_numbers_are_named_by_their_field_path(tmp_path, path, value):
    document = copy.deepcopy(DEMO_DATA)
    container, key = locate(document, path)
    container[key] = value
    error = load_error(write(tmp_path, yaml.safe_dump(document)))
    assert error is not None and error.field == path
    assert len(str(error)) < 400  # a 4,000-digit number is cut short in the message


@FUZZ
@given(path=st.sampled_from(NUMBER_PATHS), value=st.floats(-1e300, 1e300) | st.integers(-10**20, 10**20))
def test_any_finite_number_loads_or_names_a_field(tmp_path, path, value):
    # Out of range is reported where the dataclass checks it: the field itself or the record it belongs to
    # (an area that became too small, a start outside the area, a geofence that no longer contains it).
    document = copy.deepcopy(DEMO_DATA)
    container, key = locate(document, path)
    container[key] = value
    error = load_error(write(tmp_path, yaml.safe_dump(document)))
    event("loads" if error is None else "clean error")
    assert error is None or error.field


@FUZZ
@given(path=st.sampled_from(DEMO_PATHS),
       unknown=st.text(min_size=1, max_size=8).filter(str.strip).filter(str.isprintable))
def test_an_unknown_key_is_named_by_its_path(tmp_path, path, unknown):
    document = copy.deepcopy(DEMO_DATA)
    container, _ = locate(document, path)
    assume(isinstance(container, dict) and unknown not in container)  # a list item has no keys to add
    parent = parent_path(path)
    # a scenario's other sources are known keys that conflict with its inline fields (Hypothesis also tries the
    # code's own string constants, such as these)
    assume(not (parent == "scenario" and unknown in ("generator", "dataset")))
    container[unknown] = 1  # beside the node at ``path``
    error = load_error(write(tmp_path, yaml.safe_dump(document)))
    assert error is not None and error.field == (f"{parent}.{unknown}" if parent else unknown), error


@FUZZ
@given(path=st.sampled_from(DEMO_PATHS))
def test_a_missing_key_or_item_loads_with_its_default_or_is_named(tmp_path, path):
    document = copy.deepcopy(DEMO_DATA)
    container, key = locate(document, path)
    del container[key]
    error = load_error(write(tmp_path, yaml.safe_dump(document)))
    event("loads" if error is None else "clean error")
    assert error is None or error.field


# ---------------------------------------------------------------------------------------------- files

def test_files_that_are_not_missions_are_one_line_each(tmp_path):
    cases = {
        "empty": (write(tmp_path, "", "empty.yaml"), "empty file; a mission needs at least a 'scenario' section"),
        "whitespace": (write(tmp_path, "  \n\t\n", "blank.yaml"), "malformed YAML"),
        "comment only": (write(tmp_path, "# nothing\n", "comment.yaml"), "empty file"),
        "binary": (write(tmp_path, bytes(range(256)), "junk.yaml"), "not UTF-8 text"),
        "UTF-16": (write(tmp_path, "name: x\n".encode("utf-16"), "utf16.yaml"), "not UTF-8 text"),
        "a folder": (tmp_path, "is a folder, not a mission file"),
        "missing": (tmp_path / "nope.yaml", "file not found"),
        "under a file": (DEMO / "inside.yaml", "cannot read"),
        "a device": (Path("/dev/zero"), "not a regular file"),
        "too large": (write(tmp_path, "#" * 2_000_000, "big.yaml"), "far too large for a mission file"),
        "deep nesting": (write(tmp_path, "[" * 5000 + "]" * 5000, "deep.yaml"), "nested too deeply"),
        "a 5000-digit number": (write(tmp_path, "seed: " + "9" * 5000, "digits.yaml"), "malformed YAML"),
        "two documents": (write(tmp_path, "a: 1\n---\nb: 2\n", "two.yaml"), "malformed YAML"),
        "python tag": (write(tmp_path, "name: !!python/object:os.system x\n", "tag.yaml"), "malformed YAML"),
    }
    for name, (path, reason) in cases.items():
        error = load_error(path)
        assert error is not None and reason in str(error), (name, error)


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads files whatever their permissions")
def test_an_unreadable_file(tmp_path):
    path = write(tmp_path, DEMO.read_text())
    path.chmod(0)
    assert "cannot read: Permission denied" in str(load_error(path))


def test_a_fifo_is_refused_without_reading(tmp_path):
    fifo = tmp_path / "mission.yaml"
    os.mkfifo(fifo)  # reading it would block until a writer comes
    assert "not a regular file" in str(load_error(fifo))


@pytest.mark.parametrize("text, field, reason", [
    ("name: \"\\ud800\"\nscenario: {generator: {seed: 1}}", "name", "must be valid Unicode text"),
    ("flight: {altitude_m: 1.0e2}\nscenario: {generator: {seed: 1}}", "flight.altitude_m",
     "(YAML 1.1 reads an exponent as a number only with a dot and a sign, e.g. 1.0e+3"),
    ("scenario: {dataset: {root: '~no-such-user-here/x', split: test, image: a}}", "scenario.dataset.root",
     "not a usable folder path"),
    ("scenario: {dataset: {root: \"a\\0b\", split: test, image: a}}", "scenario.dataset.root",
     "not a usable folder path (embedded null byte)"),
    ("flight: {max_steps: " + "9" * 400 + "}\nscenario: {generator: {seed: 1}}", "flight.max_steps",
     "(400 characters)"),
    ("scenario: &a {home: *a}", "scenario.area", "missing required key"),
])
def test_regressions_that_used_to_crash_or_mislead(tmp_path, text, field, reason):
    error = load_error(write(tmp_path, text))
    assert error is not None and error.field == field and reason in error.reason, error


def test_byte_order_mark_and_crlf_are_accepted(tmp_path):
    text = DEMO.read_text().replace("\n", "\r\n")
    assert load_mission(write(tmp_path, "\ufeff" + text)) == load_mission(DEMO)


# ---------------------------------------------------------------------------------------------- the command

@pytest.mark.parametrize("content, mentions", [
    ("flight: {altitude_m: 500}\nscenario: {generator: {seed: 1}}", ["flight.altitude_m", "[10, 120], got 500"]),
    ("scenario: {generator: {split: tset, index: 1}}", ["scenario.generator.split", "did you mean 'test'?"]),
    ("flight: [1, 2\n", ["line 2, column 1", "malformed YAML"]),
    (b"\xff\xfe\x00junk", ["not UTF-8 text"]),
    ("", ["empty file"]),
])
def test_mission_replay_reports_the_field_and_exits_2(tmp_path, content, mentions):
    path = write(tmp_path, content)
    result = run_cli("mission", "replay", str(path), "--policy", str(POLICY), "--out", str(tmp_path / "out"))
    assert_clean_error(result, str(path), *mentions)
    assert result.error_line.startswith("hrlsac mission replay: error: ")


def test_mission_commands_as_processes(tmp_path):
    path = write(tmp_path, "flight: {altitude_m: 500}\nscenario: {generator: {seed: 1}}\n")
    for command in (["replay", str(path), "--policy", str(POLICY)],
                    ["run", str(path), "--policy", str(POLICY), "--connect", "udpin:127.0.0.1:0"]):
        result = subprocess.run([*HRLSAC, "mission", *command], capture_output=True, text=True, timeout=120)
        assert result.returncode == 2 and result.stdout == ""
        assert result.stderr == (f"hrlsac mission {command[0]}: error: {path}: flight.altitude_m: "
                                 "must be a number in [10, 120], got 500\n")
