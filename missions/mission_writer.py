"""Writing a mission file: :func:`save_mission` (atomic) and :func:`mission_to_dict` (plain YAML-ready data).

The scenario is always written inline: a generated or dataset scenario is frozen into the file (so the file no
longer depends on the generator's version), and comments are not preserved.
"""
from __future__ import annotations

import dataclasses
import enum
import numbers
import os
import secrets
from pathlib import Path
from typing import Any

import yaml

from missions.fleet import fleet_to_dict
from missions.mission import Mission
from missions.scenario import Scenario

_HEADER = "# Mission file, format described in missions/mission_file.py (written by save_mission).\n"


def mission_to_dict(mission: Mission) -> dict[str, Any]:
    """The mission as plain YAML-ready data (builtin types only), with the scenario always inline."""
    data: dict[str, Any] = {"name": mission.name, "flight": _fields_dict(mission.flight)}
    if mission.geofence is not None:
        data["geofence"] = _fields_dict(mission.geofence)
    data["scenario"] = _scenario_to_dict(mission.scenario)
    if not mission.home_altitude_known:  # written as read: an unknown altitude must not become a known 0
        del data["scenario"]["home"]["alt_m"]
    if mission.fleet is not None:
        data["fleet"] = fleet_to_dict(mission.fleet)
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
