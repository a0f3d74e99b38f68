"""Mission files' errors: one line naming the file, the field path and the allowed values, missing files and
folders, the error's attributes, the closest key suggested for a typo; and the documented example and the defaults
of a minimal file."""
from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any

import pytest
import yaml
from mission_file_helpers import BASE, DELETE, changed, error_of, write

from missions.mission import FlightSettings
from missions.mission_file import MissionFileError, load_mission, mission_from_dict
from missions.scenario import Conditions


# ------------------------------------------------------------------------------------------------ errors

FLIGHT_KEYS = "altitude_m, max_speed_mps, step_period_s, subgoal_interval, max_steps, reach_radius_m"
ALL_INLINE = "home, area, start, datum, targets, obstacles, conditions, current, seed"
EXACTLY_ONE = "give exactly one of: inline fields (home, area, datum, targets, ...), generator, dataset; got"

ERRORS = {
    "range": (changed(flight__altitude_m=500), "flight.altitude_m: must be a number in [10, 120], got 500"),
    "integer": (changed(flight__max_steps=100.5), "flight.max_steps: must be an integer, got 100.5"),
    "number type": (changed(flight__max_speed_mps="fast"), "flight.max_speed_mps: must be a number, got 'fast'"),
    "bool is not a number": (changed(flight__altitude_m=True), "flight.altitude_m: must be a number, got true"),
    "not finite": (changed(scenario__datum__north_m=float("nan")),
                   "scenario.datum.north_m: must be a finite number, got nan"),
    "section type": (changed(flight=[1]), f"flight: must be a mapping with keys {FLIGHT_KEYS}, got a list"),
    "unknown key": (changed(flight__altitud_m=60),
                    f"flight.altitud_m: unknown key, did you mean 'altitude_m'? (allowed: {FLIGHT_KEYS})"),
    "unknown top-level key": (changed(fligth={}), "fligth: unknown key, did you mean 'flight'? "
                                                  "(allowed: name, flight, geofence, scenario, fleet)"),
    "unknown key without suggestion": (changed(scenario__conditions__zzz=1),
                                       "scenario.conditions.zzz: unknown key (allowed: sea, weather, time_of_day, "
                                       "visibility, wind, wind_direction_deg)"),
    "inline is not a key": (changed(scenario={"inline": BASE["scenario"]}),
                            "scenario.inline: unknown key; write the inline scenario's fields (home, area, ...) "
                            "directly under 'scenario'"),
    "weather enum": (changed(scenario__conditions__weather="snowy"),
                     "scenario.conditions.weather: 'snowy' is not one of clear, cloudy, foggy, rainy"),
    "sea enum type": (changed(scenario__conditions__sea=2),
                      "scenario.conditions.sea: 2 is not one of calm, moderate, rough"),
    "time enum suggestion": (changed(scenario__conditions__time_of_day="nite"),
                             "scenario.conditions.time_of_day: 'nite' is not one of dawn, day, dusk, night; "
                             "did you mean 'night'?"),
    "visibility range": (changed(scenario__conditions__visibility=0.1),
                         "scenario.conditions.visibility: must be a number in [0.3, 1], got 0.1"),
    "latitude range": (changed(scenario__home__lat_deg=100),
                       "scenario.home.lat_deg: must be a number in [-90, 90], got 100"),
    "both inline and generator": (changed(scenario__generator={"split": "test", "index": 3}),
                                  f"scenario: {EXACTLY_ONE} generator and inline fields ({ALL_INLINE})"),
    "generator and dataset": (changed(scenario={"generator": {"seed": 1}, "dataset": {"root": "."}}),
                              f"scenario: {EXACTLY_ONE} generator and dataset"),
    "no scenario kind": (changed(scenario={}), f"scenario: {EXACTLY_ONE} none"),
    "no scenario": (changed(scenario=DELETE),
                    "scenario: missing required key; give inline fields, 'generator' or 'dataset'"),
    "missing inline field": (changed(scenario__datum=DELETE),
                             "scenario.datum: missing required key (an inline scenario needs home, area, datum, "
                             "targets)"),
    "missing primary": (changed(scenario__targets__0__primary=False),
                        "scenario.targets: must contain exactly one primary target, got 0"),
    "two primaries": (changed(scenario__targets__1__primary=True),
                      "scenario.targets: must contain exactly one primary target, got 2"),
    "no targets": (changed(scenario__targets=[]),
                   "scenario.targets: must list at least one target, exactly one of them with primary: true"),
    "targets type": (changed(scenario__targets={"category": "person"}),
                     "scenario.targets: must be a list, got a mapping"),
    "bool type": (changed(scenario__targets__0__primary="maybe"),
                  "scenario.targets[0].primary: must be true or false, got 'maybe'"),
    "category": (changed(scenario__targets__1__category="cat"),
                 "scenario.targets[1].category: must be one of person, boat, life_jacket, debris, floating_object, "
                 "swimmer, got 'cat'"),
    "missing target field": (changed(scenario__targets__0__north_m=DELETE),
                             "scenario.targets[0].north_m: missing required key (required here: category, north_m, "
                             "east_m)"),
    "obstacle radius": (changed(scenario__obstacles__0__radius_m=0),
                        "scenario.obstacles[0].radius_m: must be a number in [0.1, 100000], got 0"),
    "area size": (changed(scenario__area__north_max_m=-45),
                  "scenario.area: north_max_m - north_min_m and east_max_m - east_min_m must be >= 10 m, "
                  "got 5 x 1000"),
    "start outside area": (changed(scenario__start__north_m=2000),
                           "scenario.start: the start position must lie inside the search area; start (2000, 0), "
                           "area north [-50, 950], east [-500, 500]"),
    "datum sigma": (changed(scenario__datum__sigma_m=-1),
                    "scenario.datum.sigma_m: must be a number in [0, 100000], got -1"),
    "current": (changed(scenario__current__north_mps=9),
                "scenario.current.north_mps: must be a number in [-5, 5], got 9"),
    "seed": (changed(scenario__seed=-1), "scenario.seed: must be an integer >= 0, got -1"),
    "geofence": (changed(geofence__north_min_m=0),
                 "geofence: must contain the search area (scenario.area); geofence north [0, 1000], "
                 "east [-550, 550], area north [-50, 950], east [-500, 500]"),
    "name type": (changed(name=5), "name: must be a non-empty string, got 5"),
    "generator index < 0": (changed(scenario={"generator": {"split": "test", "index": -1}}),
                            "scenario.generator.index: must be an integer >= 0, got -1"),
    "generator split": (changed(scenario={"generator": {"split": "tset", "index": 1}}),
                        "scenario.generator.split: 'tset' is not one of train, val, test, test2; did you mean 'test'?"),
    "generator seed and index": (changed(scenario={"generator": {"seed": 4, "index": 1}}),
                                 "scenario.generator: give either seed, or split and index, not both"),
    "generator without index": (changed(scenario={"generator": {"split": "test"}}),
                                "scenario.generator.index: missing required key (give split and index, or seed)"),
    "dataset without image": (changed(scenario={"dataset": {"root": ".", "split": "test"}}),
                              "scenario.dataset.image: missing required key (required here: root, split, image)"),
    "not a mapping": ([1, 2], "must be a mapping with keys name, flight, geofence, scenario, fleet, got a list"),
    "malformed YAML": ("name: demo\nflight: {altitude_m: 50\nscenario: x\n",
                       "line 3, column 9: malformed YAML: expected ',' or '}', but got ':' "
                       "(while parsing a flow mapping)"),
    "duplicate key": ("name: demo\nflight:\n  altitude_m: 50\n  altitude_m: 60\n",
                      "line 4, column 3: malformed YAML: duplicate key 'altitude_m' (first at line 3)"),
    "empty file": ("", "empty file; a mission needs at least a 'scenario' section"),
    "only comments": ("# nothing here\n\n", "empty file; a mission needs at least a 'scenario' section"),
}


@pytest.mark.parametrize("data, expected", ERRORS.values(), ids=ERRORS.keys())
def test_error_names_file_field_and_allowed_values(tmp_path: Path, data: Any, expected: str) -> None:
    path = write(tmp_path, data)
    error = error_of(path)
    assert str(error) == f"{path}: {expected}"
    assert "\n" not in str(error) and isinstance(error, ValueError)
    assert error.file == str(path)


def test_missing_file_and_folder(tmp_path: Path) -> None:
    assert str(error_of(tmp_path / "nope.yaml")) == f"{tmp_path / 'nope.yaml'}: file not found"
    assert str(error_of(tmp_path)) == f"{tmp_path}: is a folder, not a mission file"


def test_error_attributes() -> None:
    with pytest.raises(MissionFileError) as caught:
        mission_from_dict(changed(flight__altitude_m=500), Path("."), source="demo.yaml")
    assert str(caught.value) == "demo.yaml: flight.altitude_m: must be a number in [10, 120], got 500"
    assert (caught.value.file, caught.value.field) == ("demo.yaml", "flight.altitude_m")
    assert caught.value.reason == "must be a number in [10, 120], got 500"


@pytest.mark.parametrize("typo, suggestion", [("altitude", "altitude_m"), ("max_step", "max_steps"),
                                              ("subgoal_intervall", "subgoal_interval"),
                                              ("reach_radius", "reach_radius_m")])
def test_closest_key_is_suggested(typo: str, suggestion: str) -> None:
    with pytest.raises(MissionFileError, match=f"flight.{typo}: unknown key, did you mean '{suggestion}'\\?"):
        mission_from_dict(changed(**{f"flight__{typo}": 1}), Path("."))


def test_the_documented_example_loads() -> None:
    import missions.mission_file as module

    doc = module.__doc__ or ""
    example = textwrap.dedent(doc[doc.index("::\n") + 3:doc.index("\nInstead of the inline fields")])
    mission = mission_from_dict(yaml.safe_load(example), Path("."))
    assert mission.name == "demo" and mission.scenario.primary.category == "person"
    assert mission.scenario.name == "hand-made" and mission.geofence is not None


def test_defaults_and_name_from_file(tmp_path: Path) -> None:
    scenario = {key: BASE["scenario"][key] for key in ("home", "area", "datum", "targets")}
    mission = load_mission(write(tmp_path, {"scenario": scenario}, "minimal.yaml"))
    assert mission.name == "minimal" and mission.flight == FlightSettings() and mission.geofence is None
    assert mission.scenario.conditions == Conditions() and mission.scenario.obstacles == ()
    assert (mission.scenario.start_north_m, mission.scenario.seed) == (0.0, 0)
