"""Reading one field of a mission file: type checks whose errors name the field's dotted path.

The readers here check what YAML gave (a mapping, a number, an integer, a string, one of some choices) and
raise :class:`InvalidField` naming the field (``scenario.targets[0].north_m``); :func:`construct` builds a
dataclass and puts that path in front of the dataclass's own range error. ``missions.mission_file`` turns an
``InvalidField`` into the one-line ``MissionFileError`` with the file's name.
"""
from __future__ import annotations

import dataclasses
import difflib
import numbers
import re
from collections.abc import Mapping, Sequence
from typing import Any

from missions.scenario import SearchArea
from missions.validation import brief, is_finite

# A float in YAML 1.1 needs a dot and a signed exponent; "1e3" or "1.0e3" stay strings (see missions/mission_file.py).
_NUMBER_LIKE = re.compile(r"^[-+]?(\d[\d_]*\.?\d*|\.\d+)[eE][-+]?\d+$")


class InvalidField(Exception):
    """A field that cannot be read; ``missions.mission_file.mission_from_dict`` turns it into a MissionFileError
    with the file's name."""

    def __init__(self, field: str, reason: str) -> None:
        super().__init__(field, reason)
        self.field = field
        self.reason = reason


def field_path(path: str, key: object) -> str:
    """Field path of ``key`` inside ``path`` (the top level has the empty path); a key with a newline or another
    unprintable character is quoted, so that the message stays one line."""
    text = str(key) if str(key).isprintable() else repr(key)
    return f"{path}.{text}" if path else text


def shown(value: Any) -> str:
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


def read_mapping(value: Any, path: str, allowed: Sequence[str], required: Sequence[str] = (),
             hints: Mapping[str, str] | None = None) -> dict[str, Any]:
    """Check that ``value`` is a mapping with only ``allowed`` keys; null values count as absent."""
    if not isinstance(value, Mapping):
        raise InvalidField(path, f"must be a mapping with keys {', '.join(allowed)}, got {shown(value)}")
    for key in value:
        if key not in allowed:
            raise InvalidField(field_path(path, key), (hints or {}).get(key) or _unknown_key(key, allowed))
    present = {key: item for key, item in value.items() if item is not None}
    for key in required:
        if key not in present:
            raise InvalidField(field_path(path, key), f"missing required key (required here: {', '.join(required)})")
    return present


def _unknown_key(key: object, allowed: Sequence[str]) -> str:
    close = difflib.get_close_matches(str(key), allowed, n=1, cutoff=0.6)
    suggestion = f", did you mean {close[0]!r}?" if close else ""
    return f"unknown key{suggestion} (allowed: {', '.join(allowed)})"


def read_number(value: Any, path: str) -> float:
    # bool is an int subclass; 'altitude_m: yes' is a mistake, not 1 m.
    if isinstance(value, str) and _NUMBER_LIKE.match(value.strip()):
        raise InvalidField(path, f"must be a number, got the string {shown(value)} (YAML 1.1 reads an exponent as a "
                             "number only with a dot and a sign, e.g. 1.0e+3; or write the digits out)")
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InvalidField(path, f"must be a number, got {shown(value)}")
    if not is_finite(value):
        raise InvalidField(path, f"must be a finite number, got {shown(value)}")
    return value  # not float(value) yet: see construct


def read_integer(value: Any, path: str, minimum: int | None = None, maximum: int | None = None) -> int:
    integer = isinstance(value, numbers.Integral) and not isinstance(value, bool)
    too_big = integer and maximum is not None and value > maximum
    allowed = (f"an integer <= {maximum}" if too_big else "an integer" if minimum is None
               else f"an integer >= {minimum}")
    if not integer or too_big or (minimum is not None and value < minimum):
        raise InvalidField(path, f"must be {allowed}, got {shown(value)}")
    return int(value)


def read_boolean(value: Any, path: str) -> bool:
    if not isinstance(value, bool):
        raise InvalidField(path, f"must be true or false, got {shown(value)}")
    return value


def read_string(value: Any, path: str) -> str:
    if not isinstance(value, str) or not value.strip():
        raise InvalidField(path, f"must be a non-empty string, got {shown(value)}")
    try:
        value.encode("utf-8")  # a lone surrogate ("\ud800" in YAML) would break every report and print later
    except UnicodeEncodeError:
        raise InvalidField(path, f"must be valid Unicode text, got {shown(value)}") from None
    return value


def read_choice(value: Any, path: str, choices: Sequence[str]) -> str:
    """One of ``choices`` (case-insensitive), with a suggestion for near misses."""
    if isinstance(value, str) and value.lower() in choices:
        return value.lower()
    close = difflib.get_close_matches(str(value).lower(), choices, n=1, cutoff=0.6)
    suggestion = f"; did you mean {close[0]!r}?" if close else ""
    raise InvalidField(path, f"{shown(value)} is not one of {', '.join(choices)}{suggestion}")


def read_numbers(value: Any, path: str, keys: Sequence[str], required: Sequence[str] | None = None) -> dict[str, float]:
    """A record of numbers (all of ``keys`` required unless ``required`` says otherwise)."""
    spec = read_mapping(value, path, keys, keys if required is None else required)
    return {key: read_number(spec[key], field_path(path, key)) for key in keys if key in spec}


def read_list(value: Any, path: str) -> list[Any]:
    if not isinstance(value, list):
        raise InvalidField(path, f"must be a list, got {shown(value)}")
    return value


_ATTRIBUTE_ERROR = re.compile(r"^[A-Za-z]\w*\.(\w+) (.*)$", re.S)  # "FlightSettings.altitude_m must be ..."
_OBJECT_ERROR = re.compile(r"^[A-Za-z]\w*: (.*)$", re.S)  # "SearchArea: north_max_m - north_min_m ..."


def construct(cls: type, path: str, paths: Mapping[str, str] | None = None,
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
            field, reason = paths.get(match[1], field_path(path, match[1])), match[2]
        else:
            match = _OBJECT_ERROR.match(message)
            reason = match[1] if match else message
            field = next((field for phrase, field in paths.items() if phrase in reason), path)
        extra = (details or {}).get(field)
        raise InvalidField(field, f"{reason}; {extra}" if extra else reason) from None
    # Validated with the numbers as written (messages say "got 500", not "got 500.0"); stored as floats so
    # that arrays built from a scenario are float arrays, whatever the YAML spelling (50 or 50.0).
    floats = {f.name: float(kwargs[f.name]) for f in dataclasses.fields(cls)
              if f.type in ("float", float, "float | None") and isinstance(kwargs.get(f.name), int)}
    return dataclasses.replace(built, **floats) if floats else built


def area_span(area: SearchArea) -> str:
    return (f"north [{area.north_min_m:g}, {area.north_max_m:g}], "
            f"east [{area.east_min_m:g}, {area.east_max_m:g}]")
