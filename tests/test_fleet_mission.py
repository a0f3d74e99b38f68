"""Fleet mission files (``missions/fleet.py``): launch points listed or on a launch line, system ids, separation and
altitude layers, the one-line errors, the round trip through the writer, and the shipped fleet demo (flown
in tests/test_fleet_replay.py)."""
from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest
import yaml
from mission_file_helpers import BASE

from missions.fleet import MAX_VEHICLES, Fleet, FleetVehicle
from missions.mission_file import MissionFileError, load_mission
from missions.mission_writer import save_mission


def with_fleet(fleet: Any, **flight: Any) -> dict[str, Any]:
    data = copy.deepcopy(BASE)
    data["fleet"] = fleet
    data["flight"].update(flight)
    return data


def load(tmp_path: Path, data: dict[str, Any]):
    path = tmp_path / "fleet.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return load_mission(path)


def error(tmp_path: Path, fleet: Any, **flight: Any) -> str:
    with pytest.raises(MissionFileError) as caught:
        load(tmp_path, with_fleet(fleet, **flight))
    message = str(caught.value)
    assert "\n" not in message and message.startswith(str(tmp_path / "fleet.yaml"))
    return message.split(": ", 1)[1]


def test_a_launch_line_spaces_the_drones_as_ardupilots_auto_offset_line(tmp_path):
    mission = load(tmp_path, with_fleet({"count": 3, "launch_line": {"bearing_deg": 90, "spacing_m": 40}}))
    assert [(v.name, v.system_id, v.north_m, v.east_m) for v in mission.fleet.vehicles] == [
        ("drone1", 1, 0.0, 0.0), ("drone2", 2, 0.0, 40.0), ("drone3", 3, 0.0, 80.0)]
    assert (mission.fleet.separation_m, mission.fleet.altitude_layer_m) == (30.0, 10.0)


def test_a_launch_line_starts_at_the_scenarios_start_and_follows_its_bearing(tmp_path):
    data = with_fleet({"count": 2, "launch_line": {"bearing_deg": 180, "spacing_m": 50}})
    data["scenario"]["start"] = {"north_m": 100, "east_m": -20}
    vehicles = load(tmp_path, data).fleet.vehicles
    assert [(v.north_m, v.east_m) for v in vehicles] == [(100.0, -20.0), (50.0, -20.0)]


def test_listed_vehicles_keep_their_names_and_system_ids(tmp_path):
    mission = load(tmp_path, with_fleet({"vehicles": [{"name": "alpha", "north_m": 0, "east_m": 0},
                                                      {"north_m": 0, "east_m": 60, "system_id": 7}],
                                         "separation_m": 50, "altitude_layer_m": 5}))
    assert mission.fleet == Fleet((FleetVehicle("alpha", 1, 0.0, 0.0), FleetVehicle("drone2", 7, 0.0, 60.0)),
                                  separation_m=50.0, altitude_layer_m=5.0)
    assert [mission.fleet.search_altitude_m(i, mission.flight.altitude_m) for i in range(2)] == [50.0, 55.0]


def test_a_mission_without_a_fleet_section_is_a_single_drone(tmp_path):
    assert load(tmp_path, copy.deepcopy(BASE)).fleet is None


@pytest.mark.parametrize("fleet, flight, expected", [
    ({"count": 3}, {}, "fleet.launch_line: missing; a count of drones needs a launch line"),
    ({"launch_line": {"bearing_deg": 0, "spacing_m": 40}}, {}, "fleet.count: missing"),
    ({"count": 2, "launch_line": {"bearing_deg": 0, "spacing_m": 40}, "vehicles": []}, {},
     "fleet: give either 'vehicles' (a list of launch points) or 'count' with 'launch_line', got both"),
    ({"separation_m": 30}, {}, "fleet: give either 'vehicles' (a list of launch points) or 'count' with 'launch_line', "
                               "got neither"),
    ({"count": MAX_VEHICLES + 1, "launch_line": {"bearing_deg": 0, "spacing_m": 40}}, {}, "fleet.count: must be"),
    ({"count": 2, "launch_line": {"bearing_deg": 0, "spacing_m": 2}}, {},
     "fleet.launch_line.spacing_m: must be in [5, 1000], got 2"),
    ({"count": 2, "launch_line": {"bearing_deg": 0, "spacing_m": 20}}, {},
     "fleet.vehicles: must launch at least separation_m (30 m) apart: drone1 and drone2 are 20.0 m apart"),
    ({"vehicles": [{"name": "a", "north_m": 0, "east_m": 0}, {"name": "a", "north_m": 0, "east_m": 60}]}, {},
     "fleet.vehicles: must each have their own name: two have a"),
    ({"vehicles": [{"north_m": 0, "east_m": 0, "system_id": 3}, {"north_m": 0, "east_m": 60, "system_id": 3}]}, {},
     "fleet.vehicles: must each have their own system_id: two have 3"),
    ({"vehicles": [{"north_m": 0, "east_m": 0, "system_id": 256}]}, {},
     "fleet.vehicles[0].system_id: must be an integer in [1, 255], got 256"),
    ({"vehicles": [{"north_m": 0}]}, {}, "fleet.vehicles[0].east_m: missing required key"),
    ({"vehicles": []}, {}, "fleet.vehicles: must list 1 to 16 drones, got 0"),
    ({"vehicles": [{"north_m": -500, "east_m": 0}]}, {},
     "fleet: must launch inside the geofence: drone1 launches at north -500 m, east 0 m"),
    ({"count": 3, "launch_line": {"bearing_deg": 90, "spacing_m": 40}, "altitude_layer_m": 40}, {"altitude_m": 50},
     "fleet: must search at most 120 m up: its highest drone would fly at 130 m"),
    ({"count": 2, "launch_line": {"bearing_deg": 90, "spacing_m": 40}, "separation_m": 1}, {},
     "fleet.separation_m: must be a number in [5, 500], got 1"),
    ({"count": 2, "launch_line": {"bearing_deg": 90, "spacing_m": 40}, "wingman": 1}, {},
     "fleet.wingman: unknown key (allowed: vehicles, count"),
])
def test_a_bad_fleet_is_refused_with_one_line_naming_the_field(tmp_path, fleet, flight, expected):
    assert error(tmp_path, fleet, **flight).startswith(expected)


def test_a_fleet_round_trips_through_the_writer_as_a_list_of_vehicles(tmp_path):
    mission = load(tmp_path, with_fleet({"count": 2, "launch_line": {"bearing_deg": 45, "spacing_m": 50},
                                         "altitude_layer_m": 0}))
    save_mission(mission, tmp_path / "copy.yaml")
    written = yaml.safe_load((tmp_path / "copy.yaml").read_text())["fleet"]
    assert [v["system_id"] for v in written["vehicles"]] == [1, 2] and "launch_line" not in written
    assert load_mission(tmp_path / "copy.yaml") == mission


def test_the_shipped_fleet_demo_is_three_drones_on_a_launch_line():
    mission = load_mission(Path(__file__).resolve().parents[1] / "missions" / "library" / "fleet-demo.yaml")
    fleet = mission.fleet
    assert [(v.name, v.system_id) for v in fleet.vehicles] == [("drone1", 1), ("drone2", 2), ("drone3", 3)]
    assert [(round(v.north_m, 6), round(v.east_m, 6)) for v in fleet.vehicles] == [(0, 0), (0, 40), (0, 80)]
    assert fleet.separation_m == 30 and fleet.altitude_layer_m == 10
