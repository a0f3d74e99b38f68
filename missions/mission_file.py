"""Mission files: one search mission written in YAML, loaded into a validated :class:`~missions.mission.Mission`.

A mission file says how to fly (``flight``), where the drone may go (``geofence``) and what to search
(``scenario``). A complete example, every key shown::

    name: demo                  # optional; defaults to the file name without .yaml
    flight:                     # optional, and so is each key; defaults from FlightSettings
      altitude_m: 50            # [10, 120] above home
      max_speed_mps: 10         # [1, 20] at full movement command
      step_period_s: 1.0        # [0.1, 10] between policy decisions
      subgoal_interval: 30      # K, [1, 1000] low-level steps per meta-controller decision
      max_steps: 1000           # [10, 100000] (the paper's preset is 10000)
      reach_radius_m: 15        # [1, 100]
    geofence: {north_min_m: -100, north_max_m: 1000, east_min_m: -550, east_max_m: 550}
                                # optional; must contain scenario.area (default: the area itself)
    scenario:                   # exactly one of: inline fields, generator, dataset
      home: {lat_deg: 47.397742, lon_deg: 8.545594, alt_m: 488}        # required; alt_m optional (AMSL)
      area: {north_min_m: -50, north_max_m: 950, east_min_m: -500, east_max_m: 500}   # required
      start: {north_m: 0, east_m: 0}                                    # optional (home)
      datum: {north_m: 600, east_m: 120, sigma_m: 80}                   # required; sigma_m optional (100)
      targets:                                                          # required; exactly one primary
        - {category: person, north_m: 640, east_m: 90, primary: true}
        - {category: debris, north_m: 300, east_m: -200}
      obstacles: [{north_m: 400, east_m: 0, radius_m: 25}]              # optional
      conditions: {sea: calm, weather: clear, time_of_day: day, visibility: 0.9, wind: 0.2,
                   wind_direction_deg: 45}                              # optional, and each key
      current: {north_mps: 0.1, east_mps: 0.0}                          # optional (still water)
      # current may add forecast_north_mps / forecast_east_mps: the current the crew's drift forecast assumes
      # (optional; default the true one, an exact forecast)
      endurance_s: 900                                                  # optional (unlimited): sortie endurance
      seed: 7                                                           # optional (0)
      name: hand-made                                                   # optional, informational
    fleet:                      # optional: several drones fly this search (missions/fleet.py)
      count: 3
      launch_line: {bearing_deg: 90, spacing_m: 40}

Instead of the inline fields, a scenario can be a reference:

* ``generator: {split: test, index: 3}`` is scenario number 3 (from 0) of the generator's ``train``, ``val``
  or ``test`` split, i.e. ``generate_scenario(scenario_seeds(split, index + 1)[index])``;
  ``generator: {seed: 12345}`` is ``generate_scenario(12345)``. Both are reproducible. ``task: SarSearch-v1``
  (optional, default ``SarSearch-v0``) draws from that task's distribution (``missions.generator.TASK_V1``:
  decoys, an endurance, a forecast error).
* ``dataset: {root: ../datasets/sar2, split: test, image: img_0042, seed: 0}`` is the scenario built from
  one labelled image of a YOLO-format dataset. ``root`` is relative to the folder of the mission file;
  ``image`` is the image's file name, with or without its extension; ``seed`` (optional, 0) is the dataset
  seed of ``YoloDataset.scenarios(split, seed=seed)``, whose scenario for that image the mission reproduces
  exactly (same drawn conditions, current and datum).

Positions are metres north/east of home (local NED frame). ``home.alt_m`` is home's altitude above mean sea
level; the runner holds the search altitude relative to the vehicle's own home (HOME_POSITION) and refuses a
mission whose launch point (``start``, at home's altitude) is farther from the vehicle's home than its tolerance;
when ``alt_m`` is left out only the horizontal distance is checked. Categories: person, boat, life_jacket, debris,
floating_object, swimmer. Conditions: ``sea`` calm/moderate/rough, ``weather`` clear/cloudy/foggy/rainy,
``time_of_day`` dawn/day/dusk/night, ``visibility`` [0.3, 1], ``wind`` [0, 1] of 15 m/s, ``wind_direction_deg``
the direction the wind blows towards. Beware YAML 1.1: ``1e3`` and ``1.0e3`` are strings there; write ``1000`` or
``1.0e+3`` (a dot and a signed exponent).

Every problem is a :class:`MissionFileError` (a ValueError) with a one-line message naming the file, the
field path and what is allowed, e.g. ``demo.yaml: flight.altitude_m: must be in [10, 120], got 500``.
Ranges are checked by the dataclasses themselves; the readers check structure and types and put the
field path in front of their messages.

This module reads the file (size, encoding, YAML without duplicate keys) and reports errors;
``missions/mission_sections.py`` reads the sections, with the field readers of ``missions/mission_fields.py``;
``missions/mission_writer.py`` writes a mission back (:func:`~missions.mission_writer.save_mission`), always
with the scenario inline.
"""
from __future__ import annotations

import os
import re
import stat
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from missions.mission import Mission
from missions.mission_fields import InvalidField
from missions.mission_sections import read_mission

LIBRARY_DIR = Path(__file__).resolve().parent / "library"
"""The bundled missions (demo.yaml, night_fog.yaml, ...)."""

MAX_FILE_BYTES = 1_000_000
"""Larger files are refused unread: a mission is a few kB, and reading /dev/zero must not take forever."""


class MissionFileError(ValueError):
    """A mission that cannot be loaded. ``str(error)`` is one line: ``<file>: <field path>: <reason>``.

    Attributes: ``file`` (as given to the loader), ``field`` (dotted path such as ``scenario.targets[0].category``;
    empty for file-level problems; ``line L, column C`` for YAML syntax errors) and ``reason``.
    """

    def __init__(self, file: str, field: str, reason: str) -> None:
        self.file = file
        self.field = field
        self.reason = re.sub(r"\s*\n\s*", " ", reason.strip())  # one line, whatever the source said
        super().__init__(": ".join(part for part in (file, field, self.reason) if part))


def load_mission(path: str | os.PathLike[str]) -> Mission:
    """Read, parse and validate a mission file; raise :class:`MissionFileError` on any problem."""
    path = Path(path)
    source = str(path)
    try:
        _check_readable_size(path)
        text = path.read_text(encoding="utf-8-sig")  # -sig: tolerate the BOM some Windows editors add
    except FileNotFoundError:
        raise MissionFileError(source, "", "file not found") from None
    except IsADirectoryError:
        raise MissionFileError(source, "", "is a folder, not a mission file") from None
    except UnicodeDecodeError as error:
        raise MissionFileError(source, "", f"not UTF-8 text (bad byte at offset {error.start})") from None
    except OSError as error:
        raise MissionFileError(source, "", f"cannot read: {error.strerror or error}") from None
    except ValueError as error:  # e.g. a NUL character in the path
        raise MissionFileError(source, "", f"not a usable file name ({error})") from None
    data = _parse_yaml(text, source)
    if data is None:
        raise MissionFileError(source, "", "empty file; a mission needs at least a 'scenario' section")
    return mission_from_dict(data, path.parent, source=source, default_name=path.stem)


def _check_readable_size(path: Path) -> None:
    """Refuse, before reading, what cannot be a mission file: a folder, a device or FIFO, a huge file."""
    status = path.stat()  # FileNotFoundError and PermissionError are reported by the caller
    if stat.S_ISDIR(status.st_mode):
        raise IsADirectoryError(path)
    if not stat.S_ISREG(status.st_mode):
        raise OSError("not a regular file (a device, FIFO or socket?); give a mission file")
    if status.st_size > MAX_FILE_BYTES:
        raise OSError(f"{status.st_size:,} bytes is far too large for a mission file (limit {MAX_FILE_BYTES:,})")


def mission_from_dict(data: Mapping[str, Any], base_dir: str | os.PathLike[str], *,
                      source: str = "<mission>", default_name: str = "mission") -> Mission:
    """Validate parsed YAML (plain dicts/lists/scalars) into a Mission.

    ``base_dir`` anchors relative paths (a dataset root); ``source`` names the origin in error messages;
    ``default_name`` is the mission's name when the data has none.
    """
    try:
        return read_mission(data, Path(base_dir), default_name)
    except InvalidField as error:
        raise MissionFileError(source, error.field, error.reason) from None


class _MissionLoader(yaml.SafeLoader):
    """SafeLoader that refuses duplicate keys: PyYAML silently keeps the last, hiding a typo'd override."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        first_line: dict[Any, int] = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":  # '<<' merges may legitimately repeat keys
                continue
            key = self.construct_object(key_node, deep=True)
            try:
                duplicate = key in first_line
            except TypeError:  # unhashable key: the base constructor reports it
                continue
            if duplicate:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r} (first at line {first_line[key] + 1})", key_node.start_mark)
            first_line[key] = key_node.start_mark.line
        return super().construct_mapping(node, deep)


def _parse_yaml(text: str, source: str) -> Any:
    try:
        return yaml.load(text, Loader=_MissionLoader)  # noqa: S506 - a SafeLoader subclass
    except RecursionError:  # PyYAML composes nested nodes recursively
        raise MissionFileError(source, "", "malformed YAML: nested too deeply to be a mission file") from None
    except yaml.MarkedYAMLError as error:
        mark = error.problem_mark or error.context_mark
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        context = f" ({error.context})" if error.context and error.problem else ""
        raise MissionFileError(source, where, f"malformed YAML: {error.problem or error.context}{context}") from None
    except yaml.YAMLError as error:
        raise MissionFileError(source, "", f"malformed YAML: {error}") from None
    except ValueError as error:  # an integer beyond Python's 4,300 digits; its advice on Python settings is cut
        raise MissionFileError(source, "", f"malformed YAML: {str(error).split(';')[0]}") from None
