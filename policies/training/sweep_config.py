"""The sweep file (YAML): a grid of training runs, validated into one :class:`RunSpec` per grid point.

Format (every key optional except ``steps``)::

    name: lr-gamma                 # default: the file's name; the sweep folder is runs/NAME
    out: runs/lr-gamma             # folder that holds one run folder per grid point (relative to the current folder)
    steps: 100000                  # environment steps of every run (TrainConfig.total_steps)
    algorithms: [hrl-sac, sac]     # default [hrl-sac]
    presets: [default]             # default [default]; "default" or "paper"
    seeds: [0, 1, 2]               # default [0]
    grid:                          # TrainConfig fields (dotted for nested ones) -> values; every combination
      learning_rate: [0.0003, 0.001]
      flight.subgoal_interval: [20, 30]
    set:                           # TrainConfig fields set in every run (as 'hrlsac train --set')
      num_envs: 8
      actor: {hidden: [128, 128]}
    max_parallel: 4                # runs at once (default: the Ray cluster's CPUs)
    retries: 1                     # restarts of a run whose worker died (each resumes from its checkpoint)

Runs are the product algorithms x presets x seeds x grid values, named ``ALGO-PRESET-seedS`` plus
``-FIELD=VALUE`` for each grid field, e.g. ``hrl-sac-default-seed0-learning_rate=0.001``. Every run's config is
``TrainConfig.from_preset(preset, algo=..., seed=..., total_steps=steps)`` with ``set`` and then its grid values
applied, exactly the config ``hrlsac train`` would build with the same options.
"""
from __future__ import annotations

import itertools
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from missions.mission_file import MissionFileError, _parse_yaml
from policies.config import TrainConfig

_TOP_KEYS = ("name", "out", "steps", "algorithms", "presets", "seeds", "grid", "set", "max_parallel", "retries")
_OWN_KEYS = ("algo", "preset", "seed", "total_steps")  # set by algorithms / presets / seeds / steps
_ALGORITHMS = ("hrl-sac", "sac")
_PRESETS = ("default", "paper")


class SweepFileError(ValueError):
    """A sweep file that cannot be used; ``str(error)`` is one line: ``<file>: <field>: <reason>``."""

    def __init__(self, file: str, field: str, reason: str) -> None:
        self.file, self.field, self.reason = file, field, reason
        super().__init__(": ".join(part for part in (file, field, reason) if part))


@dataclass(frozen=True)
class RunSpec:
    """One grid point: a training run and its folder."""

    name: str
    """Run name, also the run folder's name (``ALGO-PRESET-seedS[-FIELD=VALUE...]``)."""
    folder: Path
    """The run folder (absolute), written exactly as ``hrlsac train --out FOLDER`` would."""
    config: TrainConfig
    """The run's complete training config."""


@dataclass(frozen=True)
class SweepConfig:
    """A validated sweep file."""

    name: str
    """Sweep name (default: the file's name without extension)."""
    out: Path
    """Folder holding the run folders and sweep.json (absolute)."""
    runs: tuple[RunSpec, ...]
    """Every grid point, in grid order (algorithm, preset, seed, then grid values)."""
    max_parallel: int | None = None
    """Runs trained at once; None = one per CPU of the Ray cluster."""
    retries: int = 1
    """How many times Ray restarts a run whose worker died (the restart resumes from the run's checkpoint)."""
    grid_fields: tuple[str, ...] = field(default=())
    """The grid's (dotted) field names, for reports."""


def load_sweep(path: str | Path, out: str | Path | None = None) -> SweepConfig:
    """Read and validate a sweep file; ``out`` overrides its ``out``. Raises :class:`SweepFileError`."""
    path, source = Path(path), str(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise SweepFileError(source, "", "file not found") from None
    except OSError as error:
        raise SweepFileError(source, "", f"cannot read: {error.strerror}") from None
    try:
        data = _parse_yaml(text, source)  # the mission files' loader: refuses duplicate keys
    except MissionFileError as error:
        raise SweepFileError(source, error.field, error.reason) from None
    return sweep_from_dict(data, source, default_name=path.stem, out=out)


def sweep_from_dict(data: Any, source: str = "<sweep>", default_name: str = "sweep",
                    out: str | Path | None = None) -> SweepConfig:
    """Validate parsed YAML into a :class:`SweepConfig` (every grid point's TrainConfig is built and checked)."""
    if not isinstance(data, dict):
        raise SweepFileError(source, "", "expected a mapping of keys (steps, algorithms, seeds, grid, ...)")
    unknown = sorted(set(map(str, data)) - set(_TOP_KEYS))
    if unknown:
        raise SweepFileError(source, unknown[0], f"unknown key; allowed: {', '.join(_TOP_KEYS)}")

    def fail(key: str, reason: str) -> SweepFileError:
        return SweepFileError(source, key, reason)

    name = data.get("name", default_name)
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9._-]+", name):
        raise fail("name", f"must be letters, digits, '.', '_' or '-', got {name!r}")
    if "steps" not in data:
        raise fail("steps", "missing; give the environment steps of every run, e.g. 'steps: 100000'")
    steps = _integer(data["steps"], "steps", 1, 10**10, fail)
    algorithms = _choices(data.get("algorithms", ["hrl-sac"]), "algorithms", _ALGORITHMS, fail)
    presets = _choices(data.get("presets", ["default"]), "presets", _PRESETS, fail)
    seeds = _list(data.get("seeds", [0]), "seeds", fail)
    seeds = [_integer(seed, f"seeds[{i}]", 0, 2**31 - 1, fail) for i, seed in enumerate(seeds)]
    if len(set(seeds)) != len(seeds):
        raise fail("seeds", f"repeats a seed: {seeds}")
    fixed = _flatten(data.get("set") or {}, "set", fail)
    grid = data.get("grid") or {}
    if not isinstance(grid, dict):
        raise fail("grid", "must map TrainConfig fields to lists of values, e.g. 'learning_rate: [0.0003, 0.001]'")
    grid = {str(key): _list(values, f"grid.{key}", fail) for key, values in grid.items()}
    for key in list(fixed) + list(grid):
        if key.split(".")[0] in _OWN_KEYS:
            raise fail(key, "set by the sweep's own keys (algorithms, presets, seeds, steps); use those")
    max_parallel = data.get("max_parallel")
    if max_parallel is not None:
        max_parallel = _integer(max_parallel, "max_parallel", 1, 4096, fail)
    retries = _integer(data.get("retries", 1), "retries", 0, 100, fail)
    folder = Path(out if out is not None else data.get("out", Path("runs") / name)).resolve()

    for key, value in fixed.items():  # unknown fields are reported once, under the key that names them
        _check_field(key, f"set.{key}", fail)
    for key in grid:
        _check_field(key, f"grid.{key}", fail)
    runs, names = [], set()
    for algo, preset, seed in itertools.product(algorithms, presets, seeds):
        for values in itertools.product(*grid.values()):
            run_name = f"{algo}-{preset}-seed{seed}" + "".join(f"-{key}={_label(value)}"
                                                               for key, value in zip(grid, values))
            try:
                train_config = build_train_config(preset, algo, seed, steps, {**fixed, **dict(zip(grid, values))})
            except ValueError as error:
                raise fail("grid" if grid else "set", f"run {run_name}: {error}") from None
            if run_name in names:
                raise fail("grid", f"two grid points are both named {run_name!r}; make the values distinct")
            names.add(run_name)
            runs.append(RunSpec(run_name, folder / run_name, train_config))
    return SweepConfig(name, folder, tuple(runs), max_parallel, retries, tuple(grid))


# ---------------------------------------------------------------------------------------------- helpers

def _list(value: Any, key: str, fail) -> list:
    if not isinstance(value, list) or not value:
        raise fail(key, f"must be a non-empty list, got {value!r}")
    return value


def _choices(value: Any, key: str, allowed: tuple[str, ...], fail) -> list[str]:
    items = _list(value, key, fail)
    for i, item in enumerate(items):
        if item not in allowed:
            raise fail(f"{key}[{i}]", f"must be one of {', '.join(allowed)}, got {item!r}")
    if len(set(items)) != len(items):
        raise fail(key, f"repeats a value: {items}")
    return items


def _integer(value: Any, key: str, low: int, high: int, fail) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise fail(key, f"must be an integer in [{low}, {high}], got {value!r}")
    return value


def _flatten(value: Any, key: str, fail, prefix: str = "") -> dict[str, Any]:
    """``{"actor": {"hidden": [32]}, "gamma": 0.9}`` -> ``{"actor.hidden": [32], "gamma": 0.9}``."""
    if not isinstance(value, dict):
        raise fail(key, f"must map TrainConfig fields to values, got {value!r}")
    flat: dict[str, Any] = {}
    for name, item in value.items():
        path = f"{prefix}{name}"
        if isinstance(item, dict):
            flat.update(_flatten(item, key, fail, path + "."))
        else:
            flat[path] = item
    return flat


def build_train_config(preset: str, algo: str, seed: int, total_steps: int, overrides: dict[str, Any]) -> TrainConfig:
    """``TrainConfig.from_preset(preset, algo=, seed=, total_steps=)`` with (dotted) field overrides such as
    ``{"learning_rate": 0.001, "actor.hidden": [32, 32], "flight.max_steps": 120}``; ValueError naming the field.
    Shared by ``hrlsac train --set`` and the sweep, so both build the same config from the same options."""
    config = TrainConfig.from_preset(preset, algo=algo, seed=seed, total_steps=total_steps).to_dict()
    for dotted, value in overrides.items():
        _assign(config, dotted, value)
    try:
        return TrainConfig.from_dict(config)
    except TypeError as error:  # a nested settings class refusing a value
        raise ValueError(str(error)) from None


def field_problem(dotted: str) -> str | None:
    """Why ``dotted`` is not a settable TrainConfig field (unknown, or a group), or None if it is one."""
    try:
        _assign(TrainConfig().to_dict(), dotted, None)
    except ValueError as error:
        return str(error)
    return None


def _check_field(dotted: str, key: str, fail) -> None:
    problem = field_problem(dotted)
    if problem:
        raise fail(key, problem)


def _assign(config: dict, dotted: str, value: Any) -> None:
    """Set a (dotted) field of a TrainConfig dict, refusing unknown fields and converting YAML's spellings
    ("3e-4" is a string to YAML 1.1; 1e5 a float) to the field's type."""
    *parents, leaf = dotted.split(".")
    target = config
    for depth, part in enumerate(parents):
        if not isinstance(target.get(part), dict):
            raise ValueError(_unknown(".".join(parents[:depth + 1]), target))
        target = target[part]
    if leaf not in target:
        raise ValueError(_unknown(dotted, target))
    if isinstance(target[leaf], dict):
        raise ValueError(f"{dotted} is a group of fields ({', '.join(target[leaf])}); set one of them, "
                         f"e.g. {dotted}.{next(iter(target[leaf]))}")
    target[leaf] = _like(target[leaf], value)


def _unknown(name: str, fields: dict) -> str:
    return f"unknown TrainConfig field {name!r}; choose from {', '.join(sorted(fields))}"


def _like(current: Any, value: Any) -> Any:
    if isinstance(current, float) and isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return value
    if isinstance(current, int) and not isinstance(current, bool) and isinstance(value, float) \
            and math.isfinite(value) and value.is_integer():
        return int(value)
    return value


def _label(value: Any) -> str:
    """A grid value as a folder-name-safe label: 0.001 -> 0.001, [256, 256] -> 256x256, True -> true."""
    if isinstance(value, bool):
        text = str(value).lower()
    elif isinstance(value, (list, tuple)):
        text = "x".join(_label(item) for item in value)
    else:
        text = f"{value:g}" if isinstance(value, float) else str(value)
    return re.sub(r"[^A-Za-z0-9._+-]", "_", text)
