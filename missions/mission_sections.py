"""The sections of a mission file (flight, geofence, scenario: inline, generated or from a dataset) read into a
validated :class:`~missions.mission.Mission`. The format is described in ``missions/mission_file.py``."""
from __future__ import annotations

import dataclasses
import difflib
import enum
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from missions.fleet import read_fleet
from missions.geodesy import GeoPoint
from missions.mission import FlightSettings, Mission
from missions.mission_fields import (InvalidField, area_span, construct, field_path, read_boolean, read_choice,
                                     read_integer, read_list, read_mapping, read_number, read_numbers, read_string)
from missions.scenario import Conditions, Obstacle, Scenario, SearchArea, SeaState, Target, TimeOfDay, Weather

GENERATOR_SPLITS: tuple[str, ...] = ("train", "val", "test", "test2")
"""Splits a ``generator`` reference may name (those of missions.generator.scenario_seeds)."""

_TOP_KEYS = ("name", "flight", "geofence", "scenario", "fleet")
_INLINE_KEYS = ("home", "area", "start", "datum", "targets", "obstacles", "conditions", "current", "endurance_s",
                "seed", "name")
_CURRENT_KEYS = ("north_mps", "east_mps", "forecast_north_mps", "forecast_east_mps")
_FLAT_NAMES = {"current_forecast_north_mps": "forecast_current_north_mps",
               "current_forecast_east_mps": "forecast_current_east_mps"}
"""Scenario attributes whose flat name is not section_key (the file's current.forecast_north_mps)."""
_INLINE_REQUIRED = ("home", "area", "datum", "targets")
_AREA_KEYS = tuple(f.name for f in dataclasses.fields(SearchArea))
_ENUMS: dict[str, type[enum.Enum]] = {"SeaState": SeaState, "Weather": Weather, "TimeOfDay": TimeOfDay}
MAX_SEED = 2**64 - 1
"""Largest scenario or generator seed: numpy takes any size, but a longer one is a typo, not a seed."""


def read_mission(data: Any, base_dir: Path, default_name: str) -> Mission:
    """The mission in parsed YAML; raises :class:`InvalidField` for the first field that is wrong."""
    spec = read_mapping(data, "", _TOP_KEYS)
    if "scenario" not in spec:
        raise InvalidField("scenario", "missing required key; give inline fields, 'generator' or 'dataset'")
    name = read_string(spec["name"], "name") if "name" in spec else default_name
    flight = _flight(spec.get("flight", {}), "flight")
    geofence = construct(SearchArea, "geofence", **read_numbers(spec["geofence"], "geofence", _AREA_KEYS)) \
        if "geofence" in spec else None
    scenario = _scenario(spec["scenario"], "scenario", base_dir)
    fleet = read_fleet(spec["fleet"], "fleet", (scenario.start_north_m, scenario.start_east_m)) \
        if "fleet" in spec else None
    details = {"geofence": f"geofence {area_span(geofence)}, area {area_span(scenario.area)}"} if geofence else {}
    return construct(Mission, "", paths={"Mission.fleet": "fleet"}, details=details, scenario=scenario,
                     flight=flight, name=name, geofence=geofence, fleet=fleet,
                     home_altitude_known=_home_altitude_given(spec["scenario"]))


def _home_altitude_given(scenario: Any) -> bool:
    """False only for an inline scenario whose home leaves out alt_m (generated and dataset homes carry one)."""
    home = scenario.get("home") if isinstance(scenario, Mapping) else None
    return not isinstance(home, Mapping) or "alt_m" in home


def _flight(value: Any, path: str) -> FlightSettings:
    fields = dataclasses.fields(FlightSettings)  # the keys are the dataclass's own fields: one list to maintain
    spec = read_mapping(value, path, [f.name for f in fields])
    kwargs = {f.name: (read_integer if f.type in ("int", int) else read_number)(spec[f.name], field_path(path, f.name))
              for f in fields if f.name in spec}
    return construct(FlightSettings, path, **kwargs)


def _scenario(value: Any, path: str, base_dir: Path) -> Scenario:
    inline_hint = "unknown key; write the inline scenario's fields (home, area, ...) directly under 'scenario'"
    spec = read_mapping(value, path, _INLINE_KEYS + ("generator", "dataset"), hints={"inline": inline_hint})
    kinds = [key for key in ("generator", "dataset") if key in spec]
    inline = [key for key in _INLINE_KEYS if key in spec]
    if inline:
        kinds.append(f"inline fields ({', '.join(inline)})")
    if len(kinds) != 1:
        raise InvalidField(path, "give exactly one of: inline fields (home, area, datum, targets, ...), generator, "
                             f"dataset; got {' and '.join(kinds) or 'none'}")
    if "generator" in spec:
        return _generated(spec["generator"], field_path(path, "generator"))
    if "dataset" in spec:
        return _from_dataset(spec["dataset"], field_path(path, "dataset"), base_dir)
    return _inline(spec, path)


def _inline(spec: dict[str, Any], path: str) -> Scenario:
    for key in _INLINE_REQUIRED:
        if key not in spec:
            raise InvalidField(f"{path}.{key}", f"missing required key (an inline scenario needs "
                                            f"{', '.join(_INLINE_REQUIRED)})")
    home = read_numbers(spec["home"], f"{path}.home", ("lat_deg", "lon_deg", "alt_m"), required=("lat_deg", "lon_deg"))
    area = construct(SearchArea, f"{path}.area", **read_numbers(spec["area"], f"{path}.area", _AREA_KEYS))
    targets = tuple(_target(item, f"{path}.targets[{i}]")
                    for i, item in enumerate(read_list(spec["targets"], f"{path}.targets")))
    if not targets:
        raise InvalidField(f"{path}.targets", "must list at least one target, exactly one of them with primary: true")
    obstacles = tuple(construct(Obstacle, f"{path}.obstacles[{i}]",
                                 **read_numbers(item, f"{path}.obstacles[{i}]", ("north_m", "east_m", "radius_m")))
                      for i, item in enumerate(read_list(spec.get("obstacles", []), f"{path}.obstacles")))
    # Scenario's attributes are flat (datum_sigma_m) where the file nests them (datum.sigma_m).
    flat: dict[str, float] = {}
    for section, keys, required in (("datum", ("north_m", "east_m", "sigma_m"), ("north_m", "east_m")),
                                    ("start", ("north_m", "east_m"), ("north_m", "east_m")),
                                    ("current", _CURRENT_KEYS, ())):
        if section in spec:
            values = read_numbers(spec[section], f"{path}.{section}", keys, required)
            flat.update({_FLAT_NAMES.get(f"{section}_{key}", f"{section}_{key}"): number
                         for key, number in values.items()})
    if "endurance_s" in spec:
        flat["endurance_s"] = read_number(spec["endurance_s"], f"{path}.endurance_s")
    paths = {_FLAT_NAMES.get(f"{section}_{key}", f"{section}_{key}"): f"{path}.{section}.{key}"
             for section, key in (("datum", "sigma_m"), *(("current", key) for key in _CURRENT_KEYS))}
    paths["endurance_s"] = f"{path}.endurance_s"
    paths["start position"] = f"{path}.start"  # Scenario's object-level message about the start
    start = (flat.get("start_north_m", 0.0), flat.get("start_east_m", 0.0))
    details = {f"{path}.start": f"start ({start[0]:g}, {start[1]:g}), area {area_span(area)}"}
    return construct(Scenario, path, paths, details,
                      home=construct(GeoPoint, f"{path}.home", **home), area=area, targets=targets,
                      obstacles=obstacles, conditions=_conditions(spec.get("conditions", {}), f"{path}.conditions"),
                      seed=read_integer(spec.get("seed", 0), f"{path}.seed", minimum=0, maximum=MAX_SEED),
                      name=read_string(spec["name"], f"{path}.name") if "name" in spec else "", **flat)


def _target(value: Any, path: str) -> Target:
    spec = read_mapping(value, path, ("category", "north_m", "east_m", "primary"), ("category", "north_m", "east_m"))
    return construct(Target, path, category=spec["category"], north_m=read_number(spec["north_m"], f"{path}.north_m"),
                      east_m=read_number(spec["east_m"], f"{path}.east_m"),
                      primary=read_boolean(spec.get("primary", False), f"{path}.primary"))


def _conditions(value: Any, path: str) -> Conditions:
    fields = dataclasses.fields(Conditions)
    spec = read_mapping(value, path, [f.name for f in fields])
    kwargs: dict[str, Any] = {}
    for f in fields:
        if f.name in spec:
            enum_cls = _ENUMS.get(f.type if isinstance(f.type, str) else f.type.__name__)
            if enum_cls is None:
                kwargs[f.name] = read_number(spec[f.name], field_path(path, f.name))
            else:
                name = read_choice(spec[f.name], field_path(path, f.name), [m.name.lower() for m in enum_cls])
                kwargs[f.name] = enum_cls[name.upper()]
    return construct(Conditions, path, **kwargs)


def _generated(value: Any, path: str) -> Scenario:
    spec = read_mapping(value, path, ("split", "index", "seed", "task"))
    task = read_choice(spec.get("task", "SarSearch-v0"), f"{path}.task", ("sarsearch-v0", "sarsearch-v1"))
    seed: int | None = None
    if "seed" in spec:
        if "split" in spec or "index" in spec:
            raise InvalidField(path, "give either seed, or split and index, not both")
        seed = read_integer(spec["seed"], f"{path}.seed", minimum=0, maximum=MAX_SEED)
    else:
        for key in ("split", "index"):
            if key not in spec:
                raise InvalidField(f"{path}.{key}", "missing required key (give split and index, or seed)")
        split = read_choice(spec["split"], f"{path}.split", GENERATOR_SPLITS)
        index = read_integer(spec["index"], f"{path}.index", minimum=0)
    # Imported here: the generator pulls in more than loading an inline mission needs.
    try:
        from missions.generator import generate_scenario, scenario_seeds
    except ImportError as error:
        raise InvalidField(path, f"the scenario generator is not available ({error})") from None
    try:
        if seed is None:
            seed = scenario_seeds(split, index + 1)[index]
        if task == "sarsearch-v1":
            from missions.generator import TASK_V1

            return generate_scenario(seed, TASK_V1)
        return generate_scenario(seed)
    except ValueError as error:
        raise InvalidField(path, f"the generator refused it: {error}") from None


def _from_dataset(value: Any, path: str, base_dir: Path) -> Scenario:
    spec = read_mapping(value, path, ("root", "split", "image", "seed"), ("root", "split", "image"))
    try:
        written = Path(read_string(spec["root"], f"{path}.root")).expanduser()
        # Relative to the mission file, not the working directory: the file means the same wherever it is run.
        root = (written if written.is_absolute() else base_dir / written).resolve()
        found = root.is_dir()
    except (RuntimeError, ValueError, OSError) as error:  # ~unknown-user, a NUL character, a symlink loop
        raise InvalidField(f"{path}.root", f"not a usable folder path ({error})") from None
    if not found:
        relative = "" if written.is_absolute() else f" ({str(written)!r} is relative to {base_dir.resolve()})"
        raise InvalidField(f"{path}.root", f"dataset folder not found: {root}{relative}")
    split = read_string(spec["split"], f"{path}.split")
    image = read_string(spec["image"], f"{path}.image")
    seed = read_integer(spec.get("seed", 0), f"{path}.seed", minimum=0, maximum=MAX_SEED)
    try:
        from missions.datasets import YoloDataset
        from missions.image_scenarios import image_seed, scenario_from_item
    except ImportError as error:
        raise InvalidField(path, f"the dataset loader is not available ({error})") from None
    try:
        dataset = YoloDataset(root)
    except (OSError, ValueError) as error:
        raise InvalidField(f"{path}.root", f"not a usable YOLO dataset: {error}") from None
    try:
        items = dataset.items(split)
    except (OSError, ValueError, KeyError) as error:
        raise InvalidField(f"{path}.split", f"cannot list split {split!r}: {error}") from None
    by_name = {}
    for index, item in enumerate(items):
        image_path = Path(item.image_path)
        by_name.setdefault(image_path.name, (index, item))
        by_name.setdefault(image_path.stem, (index, item))
    if image not in by_name:
        stems = sorted({Path(item.image_path).stem for item in items})
        close = difflib.get_close_matches(image, stems, n=1, cutoff=0.6)
        suggestion = f"; did you mean {close[0]!r}?" if close else ""
        raise InvalidField(f"{path}.image", f"{image!r} not found in split {split!r} of {root} "
                                        f"({len(items)} images){suggestion}")
    try:
        index, item = by_name[image]
        # The same per-image seed as YoloDataset.scenarios(split, seed=seed): the mission flies exactly the
        # scenario an evaluation on that split uses for this image.
        scenario = scenario_from_item(item, seed=image_seed(seed, split, index))
    except (OSError, ValueError) as error:  # e.g. an unreadable image (its size sets the area's height)
        raise InvalidField(f"{path}.image", f"cannot build a scenario from {image!r}: {error}") from None
    if scenario is None:
        raise InvalidField(f"{path}.image",
                           f"{image!r} yields no scenario (no labelled object can be the primary target)")
    return scenario
