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
Ranges are checked by the dataclasses themselves; this module checks structure and types and puts the
field path in front of their messages.

:func:`save_mission` always writes the scenario inline: a generated or dataset scenario is frozen into the
file (so the file no longer depends on the generator's version), and comments are not preserved.
"""
from __future__ import annotations

import dataclasses
import difflib
import enum
import numbers
import os
import re
import secrets
import stat
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

from missions.geodesy import GeoPoint
from missions.mission import FlightSettings, Mission
from missions.scenario import Conditions, Obstacle, Scenario, SearchArea, SeaState, Target, TimeOfDay, Weather
from missions.validation import brief, is_finite

LIBRARY_DIR = Path(__file__).resolve().parent / "library"
"""The bundled missions (demo.yaml, night_fog.yaml, ...)."""

GENERATOR_SPLITS: tuple[str, ...] = ("train", "val", "test")
"""Splits a ``generator`` reference may name (those of missions.generator.scenario_seeds)."""

_TOP_KEYS = ("name", "flight", "geofence", "scenario")
_INLINE_KEYS = ("home", "area", "start", "datum", "targets", "obstacles", "conditions", "current", "endurance_s",
                "seed", "name")
_CURRENT_KEYS = ("north_mps", "east_mps", "forecast_north_mps", "forecast_east_mps")
_FLAT_NAMES = {"current_forecast_north_mps": "forecast_current_north_mps",
               "current_forecast_east_mps": "forecast_current_east_mps"}
"""Scenario attributes whose flat name is not section_key (the file's current.forecast_north_mps)."""
_INLINE_REQUIRED = ("home", "area", "datum", "targets")
_AREA_KEYS = tuple(f.name for f in dataclasses.fields(SearchArea))
_ENUMS: dict[str, type[enum.Enum]] = {"SeaState": SeaState, "Weather": Weather, "TimeOfDay": TimeOfDay}
_HEADER = "# Mission file, format described in missions/mission_file.py (written by save_mission).\n"
MAX_SEED = 2**64 - 1
"""Largest scenario or generator seed: numpy takes any size, but a longer one is a typo, not a seed."""
MAX_FILE_BYTES = 1_000_000
"""Larger files are refused unread: a mission is a few kB, and reading /dev/zero must not take forever."""
# A float in YAML 1.1 needs a dot and a signed exponent; "1e3" or "1.0e3" stay strings (see the module notes).
_NUMBER_LIKE = re.compile(r"^[-+]?(\d[\d_]*\.?\d*|\.\d+)[eE][-+]?\d+$")


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


class _Invalid(Exception):
    """Raised while reading a mission; mission_from_dict turns it into a MissionFileError with the file name."""

    def __init__(self, field: str, reason: str) -> None:
        super().__init__(field, reason)
        self.field = field
        self.reason = reason


# ---------------------------------------------------------------------------------------------- public API

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
        return _mission(data, Path(base_dir), default_name)
    except _Invalid as error:
        raise MissionFileError(source, error.field, error.reason) from None


def mission_to_dict(mission: Mission) -> dict[str, Any]:
    """The mission as plain YAML-ready data (builtin types only), with the scenario always inline."""
    data: dict[str, Any] = {"name": mission.name, "flight": _fields_dict(mission.flight)}
    if mission.geofence is not None:
        data["geofence"] = _fields_dict(mission.geofence)
    data["scenario"] = _scenario_to_dict(mission.scenario)
    if not mission.home_altitude_known:  # written as read: an unknown altitude must not become a known 0
        del data["scenario"]["home"]["alt_m"]
    return data


def save_mission(mission: Mission, path: str | os.PathLike[str]) -> None:
    """Write ``mission`` as YAML; atomic (temp file + os.replace), so readers never see half a file."""
    path = Path(path)
    text = _HEADER + yaml.dump(_styled(mission_to_dict(mission), 0), Dumper=_Dumper, sort_keys=False,
                               default_flow_style=False, allow_unicode=True, width=110)
    # Our own temp name (not mkstemp, which creates 0600) so the file gets the usual umask-based mode;
    # same folder so os.replace is a rename within one file system.
    temp = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp")
    try:
        fd = os.open(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(text)
            handle.flush()
            os.fsync(handle.fileno())  # data on disk before the rename makes it visible
        os.replace(temp, path)
    except BaseException:
        temp.unlink(missing_ok=True)
        raise


# ---------------------------------------------------------------------------------------------- YAML

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


class _Flow(dict):
    """A mapping saved in flow style ({a: 1, b: 2}): small records such as a target stay on one line."""


class _Dumper(yaml.SafeDumper):
    def increase_indent(self, flow: bool = False, indentless: bool = False) -> None:
        super().increase_indent(flow, False)  # indent list items under their key, as people write them


_Dumper.add_representer(
    _Flow, lambda dumper, data: dumper.represent_mapping("tag:yaml.org,2002:map", data.items(), flow_style=True))


def _styled(value: Any, depth: int) -> Any:
    """Mark records of scalars below the top two levels for flow style (sections stay in block style)."""
    if isinstance(value, dict):
        items = {key: _styled(item, depth + 1) for key, item in value.items()}
        leaf = not any(isinstance(item, (dict, list)) for item in value.values())
        return _Flow(items) if leaf and depth >= 2 else items
    if isinstance(value, list):
        return [_styled(item, depth + 1) for item in value]
    return value


# ---------------------------------------------------------------------------------------------- readers

def _join(path: str, key: object) -> str:
    """Field path of ``key`` inside ``path`` (the top level has the empty path); a key with a newline or another
    unprintable character is quoted, so that the message stays one line."""
    text = str(key) if str(key).isprintable() else repr(key)
    return f"{path}.{text}" if path else text


def _shown(value: Any) -> str:
    """A value as the user wrote it in YAML, for messages."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if value is None:
        return "null"
    if isinstance(value, Mapping):
        return "a mapping"
    if isinstance(value, list):
        return "a list"
    return brief(value)


def _mapping(value: Any, path: str, allowed: Sequence[str], required: Sequence[str] = (),
             hints: Mapping[str, str] | None = None) -> dict[str, Any]:
    """Check that ``value`` is a mapping with only ``allowed`` keys; null values count as absent."""
    if not isinstance(value, Mapping):
        raise _Invalid(path, f"must be a mapping with keys {', '.join(allowed)}, got {_shown(value)}")
    for key in value:
        if key not in allowed:
            raise _Invalid(_join(path, key), (hints or {}).get(key) or _unknown_key(key, allowed))
    present = {key: item for key, item in value.items() if item is not None}
    for key in required:
        if key not in present:
            raise _Invalid(_join(path, key), f"missing required key (required here: {', '.join(required)})")
    return present


def _unknown_key(key: object, allowed: Sequence[str]) -> str:
    close = difflib.get_close_matches(str(key), allowed, n=1, cutoff=0.6)
    suggestion = f", did you mean {close[0]!r}?" if close else ""
    return f"unknown key{suggestion} (allowed: {', '.join(allowed)})"


def _number(value: Any, path: str) -> float:
    # bool is an int subclass; 'altitude_m: yes' is a mistake, not 1 m.
    if isinstance(value, str) and _NUMBER_LIKE.match(value.strip()):
        raise _Invalid(path, f"must be a number, got the string {_shown(value)} (YAML 1.1 reads an exponent as a "
                             "number only with a dot and a sign, e.g. 1.0e+3; or write the digits out)")
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise _Invalid(path, f"must be a number, got {_shown(value)}")
    if not is_finite(value):
        raise _Invalid(path, f"must be a finite number, got {_shown(value)}")
    return value  # not float(value) yet: see _construct


def _integer(value: Any, path: str, minimum: int | None = None, maximum: int | None = None) -> int:
    integer = isinstance(value, numbers.Integral) and not isinstance(value, bool)
    too_big = integer and maximum is not None and value > maximum
    allowed = (f"an integer <= {maximum}" if too_big else "an integer" if minimum is None
               else f"an integer >= {minimum}")
    if not integer or too_big or (minimum is not None and value < minimum):
        raise _Invalid(path, f"must be {allowed}, got {_shown(value)}")
    return int(value)


def _boolean(value: Any, path: str) -> bool:
    if not isinstance(value, bool):
        raise _Invalid(path, f"must be true or false, got {_shown(value)}")
    return value


def _string(value: Any, path: str) -> str:
    if not isinstance(value, str) or not value.strip():
        raise _Invalid(path, f"must be a non-empty string, got {_shown(value)}")
    try:
        value.encode("utf-8")  # a lone surrogate ("\ud800" in YAML) would break every report and print later
    except UnicodeEncodeError:
        raise _Invalid(path, f"must be valid Unicode text, got {_shown(value)}") from None
    return value


def _choice(value: Any, path: str, choices: Sequence[str]) -> str:
    """One of ``choices`` (case-insensitive), with a suggestion for near misses."""
    if isinstance(value, str) and value.lower() in choices:
        return value.lower()
    close = difflib.get_close_matches(str(value).lower(), choices, n=1, cutoff=0.6)
    suggestion = f"; did you mean {close[0]!r}?" if close else ""
    raise _Invalid(path, f"{_shown(value)} is not one of {', '.join(choices)}{suggestion}")


def _numbers(value: Any, path: str, keys: Sequence[str], required: Sequence[str] | None = None) -> dict[str, float]:
    """A record of numbers (all of ``keys`` required unless ``required`` says otherwise)."""
    spec = _mapping(value, path, keys, keys if required is None else required)
    return {key: _number(spec[key], _join(path, key)) for key in keys if key in spec}


def _list(value: Any, path: str) -> list[Any]:
    if not isinstance(value, list):
        raise _Invalid(path, f"must be a list, got {_shown(value)}")
    return value


_ATTRIBUTE_ERROR = re.compile(r"^[A-Za-z]\w*\.(\w+) (.*)$", re.S)  # "FlightSettings.altitude_m must be ..."
_OBJECT_ERROR = re.compile(r"^[A-Za-z]\w*: (.*)$", re.S)  # "SearchArea: north_max_m - north_min_m ..."


def _construct(cls: type, path: str, paths: Mapping[str, str] | None = None,
               details: Mapping[str, str] | None = None, **kwargs: Any) -> Any:
    """``cls(**kwargs)``, its own ValueError re-raised under the field path of the attribute it names.

    ``paths`` maps a dataclass attribute (or a phrase of an object-level message) to its field path in the
    file, where the two differ; ``details`` adds context to the message for a given field path.
    """
    try:
        built = cls(**kwargs)
    except ValueError as error:
        message, paths = str(error), paths or {}
        match = _ATTRIBUTE_ERROR.match(message)
        if match:
            field, reason = paths.get(match[1], _join(path, match[1])), match[2]
        else:
            match = _OBJECT_ERROR.match(message)
            reason = match[1] if match else message
            field = next((field for phrase, field in paths.items() if phrase in reason), path)
        extra = (details or {}).get(field)
        raise _Invalid(field, f"{reason}; {extra}" if extra else reason) from None
    # Validated with the numbers as written (messages say "got 500", not "got 500.0"); stored as floats so
    # that arrays built from a scenario are float arrays, whatever the YAML spelling (50 or 50.0).
    floats = {f.name: float(kwargs[f.name]) for f in dataclasses.fields(cls)
              if f.type in ("float", float, "float | None") and isinstance(kwargs.get(f.name), int)}
    return dataclasses.replace(built, **floats) if floats else built


def _span(area: SearchArea) -> str:
    return (f"north [{area.north_min_m:g}, {area.north_max_m:g}], "
            f"east [{area.east_min_m:g}, {area.east_max_m:g}]")


# ---------------------------------------------------------------------------------------------- sections

def _mission(data: Any, base_dir: Path, default_name: str) -> Mission:
    spec = _mapping(data, "", _TOP_KEYS)
    if "scenario" not in spec:
        raise _Invalid("scenario", "missing required key; give inline fields, 'generator' or 'dataset'")
    name = _string(spec["name"], "name") if "name" in spec else default_name
    flight = _flight(spec.get("flight", {}), "flight")
    geofence = _construct(SearchArea, "geofence", **_numbers(spec["geofence"], "geofence", _AREA_KEYS)) \
        if "geofence" in spec else None
    scenario = _scenario(spec["scenario"], "scenario", base_dir)
    details = {"geofence": f"geofence {_span(geofence)}, area {_span(scenario.area)}"} if geofence else {}
    return _construct(Mission, "", details=details, scenario=scenario, flight=flight, name=name, geofence=geofence,
                      home_altitude_known=_home_altitude_given(spec["scenario"]))


def _home_altitude_given(scenario: Any) -> bool:
    """False only for an inline scenario whose home leaves out alt_m (generated and dataset homes carry one)."""
    home = scenario.get("home") if isinstance(scenario, Mapping) else None
    return not isinstance(home, Mapping) or "alt_m" in home


def _flight(value: Any, path: str) -> FlightSettings:
    fields = dataclasses.fields(FlightSettings)  # the keys are the dataclass's own fields: one list to maintain
    spec = _mapping(value, path, [f.name for f in fields])
    kwargs = {f.name: (_integer if f.type in ("int", int) else _number)(spec[f.name], _join(path, f.name))
              for f in fields if f.name in spec}
    return _construct(FlightSettings, path, **kwargs)


def _scenario(value: Any, path: str, base_dir: Path) -> Scenario:
    inline_hint = "unknown key; write the inline scenario's fields (home, area, ...) directly under 'scenario'"
    spec = _mapping(value, path, _INLINE_KEYS + ("generator", "dataset"), hints={"inline": inline_hint})
    kinds = [key for key in ("generator", "dataset") if key in spec]
    inline = [key for key in _INLINE_KEYS if key in spec]
    if inline:
        kinds.append(f"inline fields ({', '.join(inline)})")
    if len(kinds) != 1:
        raise _Invalid(path, "give exactly one of: inline fields (home, area, datum, targets, ...), generator, "
                             f"dataset; got {' and '.join(kinds) or 'none'}")
    if "generator" in spec:
        return _generated(spec["generator"], _join(path, "generator"))
    if "dataset" in spec:
        return _from_dataset(spec["dataset"], _join(path, "dataset"), base_dir)
    return _inline(spec, path)


def _inline(spec: dict[str, Any], path: str) -> Scenario:
    for key in _INLINE_REQUIRED:
        if key not in spec:
            raise _Invalid(f"{path}.{key}", f"missing required key (an inline scenario needs "
                                            f"{', '.join(_INLINE_REQUIRED)})")
    home = _numbers(spec["home"], f"{path}.home", ("lat_deg", "lon_deg", "alt_m"), required=("lat_deg", "lon_deg"))
    area = _construct(SearchArea, f"{path}.area", **_numbers(spec["area"], f"{path}.area", _AREA_KEYS))
    targets = tuple(_target(item, f"{path}.targets[{i}]")
                    for i, item in enumerate(_list(spec["targets"], f"{path}.targets")))
    if not targets:
        raise _Invalid(f"{path}.targets", "must list at least one target, exactly one of them with primary: true")
    obstacles = tuple(_construct(Obstacle, f"{path}.obstacles[{i}]",
                                 **_numbers(item, f"{path}.obstacles[{i}]", ("north_m", "east_m", "radius_m")))
                      for i, item in enumerate(_list(spec.get("obstacles", []), f"{path}.obstacles")))
    # Scenario's attributes are flat (datum_sigma_m) where the file nests them (datum.sigma_m).
    flat: dict[str, float] = {}
    for section, keys, required in (("datum", ("north_m", "east_m", "sigma_m"), ("north_m", "east_m")),
                                    ("start", ("north_m", "east_m"), ("north_m", "east_m")),
                                    ("current", _CURRENT_KEYS, ())):
        if section in spec:
            values = _numbers(spec[section], f"{path}.{section}", keys, required)
            flat.update({_FLAT_NAMES.get(f"{section}_{key}", f"{section}_{key}"): number
                         for key, number in values.items()})
    if "endurance_s" in spec:
        flat["endurance_s"] = _number(spec["endurance_s"], f"{path}.endurance_s")
    paths = {_FLAT_NAMES.get(f"{section}_{key}", f"{section}_{key}"): f"{path}.{section}.{key}"
             for section, key in (("datum", "sigma_m"), *(("current", key) for key in _CURRENT_KEYS))}
    paths["endurance_s"] = f"{path}.endurance_s"
    paths["start position"] = f"{path}.start"  # Scenario's object-level message about the start
    start = (flat.get("start_north_m", 0.0), flat.get("start_east_m", 0.0))
    details = {f"{path}.start": f"start ({start[0]:g}, {start[1]:g}), area {_span(area)}"}
    return _construct(Scenario, path, paths, details,
                      home=_construct(GeoPoint, f"{path}.home", **home), area=area, targets=targets,
                      obstacles=obstacles, conditions=_conditions(spec.get("conditions", {}), f"{path}.conditions"),
                      seed=_integer(spec.get("seed", 0), f"{path}.seed", minimum=0, maximum=MAX_SEED),
                      name=_string(spec["name"], f"{path}.name") if "name" in spec else "", **flat)


def _target(value: Any, path: str) -> Target:
    spec = _mapping(value, path, ("category", "north_m", "east_m", "primary"), ("category", "north_m", "east_m"))
    return _construct(Target, path, category=spec["category"], north_m=_number(spec["north_m"], f"{path}.north_m"),
                      east_m=_number(spec["east_m"], f"{path}.east_m"),
                      primary=_boolean(spec.get("primary", False), f"{path}.primary"))


def _conditions(value: Any, path: str) -> Conditions:
    fields = dataclasses.fields(Conditions)
    spec = _mapping(value, path, [f.name for f in fields])
    kwargs: dict[str, Any] = {}
    for f in fields:
        if f.name in spec:
            enum_cls = _ENUMS.get(f.type if isinstance(f.type, str) else f.type.__name__)
            if enum_cls is None:
                kwargs[f.name] = _number(spec[f.name], _join(path, f.name))
            else:
                name = _choice(spec[f.name], _join(path, f.name), [m.name.lower() for m in enum_cls])
                kwargs[f.name] = enum_cls[name.upper()]
    return _construct(Conditions, path, **kwargs)


def _generated(value: Any, path: str) -> Scenario:
    spec = _mapping(value, path, ("split", "index", "seed", "task"))
    task = _choice(spec.get("task", "SarSearch-v0"), f"{path}.task", ("sarsearch-v0", "sarsearch-v1"))
    seed: int | None = None
    if "seed" in spec:
        if "split" in spec or "index" in spec:
            raise _Invalid(path, "give either seed, or split and index, not both")
        seed = _integer(spec["seed"], f"{path}.seed", minimum=0, maximum=MAX_SEED)
    else:
        for key in ("split", "index"):
            if key not in spec:
                raise _Invalid(f"{path}.{key}", "missing required key (give split and index, or seed)")
        split = _choice(spec["split"], f"{path}.split", GENERATOR_SPLITS)
        index = _integer(spec["index"], f"{path}.index", minimum=0)
    # Imported here: the generator pulls in more than loading an inline mission needs.
    try:
        from missions.generator import generate_scenario, scenario_seeds
    except ImportError as error:
        raise _Invalid(path, f"the scenario generator is not available ({error})") from None
    try:
        if seed is None:
            seed = scenario_seeds(split, index + 1)[index]
        if task == "sarsearch-v1":
            from missions.generator import TASK_V1

            return generate_scenario(seed, TASK_V1)
        return generate_scenario(seed)
    except ValueError as error:
        raise _Invalid(path, f"the generator refused it: {error}") from None


def _from_dataset(value: Any, path: str, base_dir: Path) -> Scenario:
    spec = _mapping(value, path, ("root", "split", "image", "seed"), ("root", "split", "image"))
    try:
        written = Path(_string(spec["root"], f"{path}.root")).expanduser()
        # Relative to the mission file, not the working directory: the file means the same wherever it is run.
        root = (written if written.is_absolute() else base_dir / written).resolve()
        found = root.is_dir()
    except (RuntimeError, ValueError, OSError) as error:  # ~unknown-user, a NUL character, a symlink loop
        raise _Invalid(f"{path}.root", f"not a usable folder path ({error})") from None
    if not found:
        relative = "" if written.is_absolute() else f" ({str(written)!r} is relative to {base_dir.resolve()})"
        raise _Invalid(f"{path}.root", f"dataset folder not found: {root}{relative}")
    split = _string(spec["split"], f"{path}.split")
    image = _string(spec["image"], f"{path}.image")
    seed = _integer(spec.get("seed", 0), f"{path}.seed", minimum=0, maximum=MAX_SEED)
    try:
        from missions.datasets import YoloDataset, image_seed, scenario_from_item
    except ImportError as error:
        raise _Invalid(path, f"the dataset loader is not available ({error})") from None
    try:
        dataset = YoloDataset(root)
    except (OSError, ValueError) as error:
        raise _Invalid(f"{path}.root", f"not a usable YOLO dataset: {error}") from None
    try:
        items = dataset.items(split)
    except (OSError, ValueError, KeyError) as error:
        raise _Invalid(f"{path}.split", f"cannot list split {split!r}: {error}") from None
    by_name = {}
    for index, item in enumerate(items):
        image_path = Path(item.image_path)
        by_name.setdefault(image_path.name, (index, item))
        by_name.setdefault(image_path.stem, (index, item))
    if image not in by_name:
        stems = sorted({Path(item.image_path).stem for item in items})
        close = difflib.get_close_matches(image, stems, n=1, cutoff=0.6)
        suggestion = f"; did you mean {close[0]!r}?" if close else ""
        raise _Invalid(f"{path}.image", f"{image!r} not found in split {split!r} of {root} "
                                        f"({len(items)} images){suggestion}")
    try:
        index, item = by_name[image]
        # The same per-image seed as YoloDataset.scenarios(split, seed=seed): the mission flies exactly the
        # scenario an evaluation on that split uses for this image.
        scenario = scenario_from_item(item, seed=image_seed(seed, split, index))
    except (OSError, ValueError) as error:  # e.g. an unreadable image (its size sets the area's height)
        raise _Invalid(f"{path}.image", f"cannot build a scenario from {image!r}: {error}") from None
    if scenario is None:
        raise _Invalid(f"{path}.image", f"{image!r} yields no scenario (no labelled object can be the primary target)")
    return scenario


# ---------------------------------------------------------------------------------------------- writers

def _plain(value: Any) -> Any:
    """Builtin equivalent of a field value (numpy scalars from the generator included; enums by name)."""
    if isinstance(value, enum.Enum):
        return value.name.lower()
    if isinstance(value, bool) or isinstance(value, str):
        return value
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real):
        return float(value)
    return value


def _fields_dict(obj: Any) -> dict[str, Any]:
    return {f.name: _plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}


def _scenario_to_dict(scenario: Scenario) -> dict[str, Any]:
    s = scenario
    data: dict[str, Any] = {
        "home": _fields_dict(s.home),
        "area": _fields_dict(s.area),
        "start": {"north_m": _plain(s.start_north_m), "east_m": _plain(s.start_east_m)},
        "datum": {"north_m": _plain(s.datum_north_m), "east_m": _plain(s.datum_east_m),
                  "sigma_m": _plain(s.datum_sigma_m)},
        # primary is written only where true: the one victim stands out when reading the file.
        "targets": [{"category": str(t.category), "north_m": _plain(t.north_m), "east_m": _plain(t.east_m),
                     **({"primary": True} if t.primary else {})} for t in s.targets],
        "obstacles": [_fields_dict(o) for o in s.obstacles],
        "conditions": _fields_dict(s.conditions),
        "current": {"north_mps": _plain(s.current_north_mps), "east_mps": _plain(s.current_east_mps)},
        "seed": int(s.seed),
    }
    for key, value in (("forecast_north_mps", s.forecast_current_north_mps),
                       ("forecast_east_mps", s.forecast_current_east_mps)):
        if value is not None:
            data["current"][key] = _plain(value)
    if s.endurance_s is not None:
        data["endurance_s"] = _plain(s.endurance_s)
    if s.name:
        data["name"] = str(s.name)
    return data
