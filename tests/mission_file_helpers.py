"""What the mission-file tests share (tests/test_mission_file_*.py, test_fleet_mission.py): a complete inline
mission (BASE) and edited copies of it, writing one to a file and the error loading it gives. Not a test module
(pytest does not collect it)."""
from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest
import yaml

from missions.mission_file import MissionFileError, load_mission


NEEDS_GENERATOR = "missions.generator (generate_scenario, scenario_seeds) is not written yet"
NEEDS_DATASETS = "missions.datasets (YoloDataset, scenario_from_item) is not written yet"

BASE: dict[str, Any] = {
    "name": "base",
    "flight": {"altitude_m": 50, "max_speed_mps": 10, "step_period_s": 1.0, "subgoal_interval": 30,
               "max_steps": 1000, "reach_radius_m": 15},
    "geofence": {"north_min_m": -100, "north_max_m": 1000, "east_min_m": -550, "east_max_m": 550},
    "scenario": {
        "home": {"lat_deg": 47.3977, "lon_deg": 8.5456, "alt_m": 488},
        "area": {"north_min_m": -50, "north_max_m": 950, "east_min_m": -500, "east_max_m": 500},
        "start": {"north_m": 0, "east_m": 0},
        "datum": {"north_m": 600, "east_m": 120, "sigma_m": 80},
        "targets": [{"category": "person", "north_m": 640, "east_m": 90, "primary": True},
                    {"category": "debris", "north_m": 300, "east_m": -200}],
        "obstacles": [{"north_m": 400, "east_m": 0, "radius_m": 25}],
        "conditions": {"sea": "calm", "weather": "clear", "time_of_day": "day", "visibility": 0.9, "wind": 0.2,
                       "wind_direction_deg": 45},
        "current": {"north_mps": 0.1, "east_mps": 0.0},
        "seed": 7,
    },
}
DELETE = object()


def changed(**edits: Any) -> dict[str, Any]:
    """A deep copy of BASE with edits; a key is a field path with '__' between parts (list indices as numbers)."""
    data = copy.deepcopy(BASE)
    for dotted, value in edits.items():
        *parents, last = [int(part) if part.isdigit() else part for part in dotted.split("__")]
        node = data
        for part in parents:
            node = node[part]
        if value is DELETE:
            del node[last]
        else:
            node[last] = value
    return data


def write(folder: Path, data: Any, name: str = "m.yaml") -> Path:
    path = folder / name
    path.write_text(data if isinstance(data, str) else yaml.safe_dump(data, sort_keys=False))
    return path


def error_of(path: Path) -> MissionFileError:
    with pytest.raises(MissionFileError) as caught:
        load_mission(path)
    return caught.value
