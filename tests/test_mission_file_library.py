"""Mission files: the bundled library (every mission loads, the documented ones are what the docs say) and round
trips (the library's files, numbers, plain YAML data, atomic saves, and a property test over drawn missions)."""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mission_file_helpers import BASE, NEEDS_GENERATOR, changed, write

from missions.geodesy import GeoPoint
from missions.mission import FlightSettings, Mission
from missions.mission_file import LIBRARY_DIR, load_mission, mission_from_dict
from missions.mission_writer import mission_to_dict, save_mission
from missions.scenario import (CATEGORIES, Conditions, Obstacle, Scenario, SearchArea, SeaState, Target, TimeOfDay,
                               Weather)


# ------------------------------------------------------------------------------------------------ library

LIBRARY = sorted(LIBRARY_DIR.glob("*.yaml"))


def test_library_has_the_bundled_missions() -> None:
    assert {p.name for p in LIBRARY} >= {"demo.yaml", "night_fog.yaml", "generated_test_003.yaml",
                                         "open_ocean_paper.yaml"}
    for path in LIBRARY:
        assert path.read_text().startswith("# "), f"{path.name} needs a comment header"


@pytest.mark.parametrize("path", LIBRARY, ids=lambda p: p.name)
def test_every_library_mission_loads(path: Path) -> None:
    if "generator" in yaml.safe_load(path.read_text())["scenario"]:
        pytest.importorskip("missions.generator", reason=NEEDS_GENERATOR)
    mission = load_mission(path)
    assert isinstance(mission, Mission)
    assert mission.name == path.stem
    assert sum(t.primary for t in mission.scenario.targets) == 1


def test_demo_is_the_documented_easy_search() -> None:
    mission = load_mission(LIBRARY_DIR / "demo.yaml")
    scenario, person = mission.scenario, mission.scenario.primary
    assert (mission.flight.subgoal_interval, mission.flight.max_steps) == (30, 1000)
    assert person.category == "person" and 400 <= math.hypot(person.north_m, person.east_m) <= 600
    assert scenario.conditions.sea is SeaState.CALM and scenario.conditions.weather is Weather.CLEAR
    assert scenario.conditions.time_of_day is TimeOfDay.DAY
    assert len(scenario.targets) >= 3
    # The obstacle lies on the straight line from home to the person.
    (obstacle,) = scenario.obstacles
    along = (obstacle.north_m * person.north_m + obstacle.east_m * person.east_m) / math.hypot(person.north_m,
                                                                                               person.east_m)
    across = abs(obstacle.north_m * person.east_m - obstacle.east_m * person.north_m) / math.hypot(person.north_m,
                                                                                                   person.east_m)
    assert 0 < along < math.hypot(person.north_m, person.east_m) and across < obstacle.radius_m


def test_night_fog_has_hard_conditions() -> None:
    conditions = load_mission(LIBRARY_DIR / "night_fog.yaml").scenario.conditions
    assert (conditions.time_of_day, conditions.weather, conditions.sea) == (TimeOfDay.NIGHT, Weather.FOGGY,
                                                                            SeaState.ROUGH)
    assert conditions.visibility == 0.4


def test_paper_preset_flight_settings() -> None:
    pytest.importorskip("missions.generator", reason=NEEDS_GENERATOR)
    mission = load_mission(LIBRARY_DIR / "open_ocean_paper.yaml")
    assert (mission.flight.max_steps, mission.flight.subgoal_interval) == (10_000, 30)


# ------------------------------------------------------------------------------------------------ round trip

@pytest.mark.parametrize("name", ["demo.yaml", "night_fog.yaml"])
def test_library_round_trip(tmp_path: Path, name: str) -> None:
    mission = load_mission(LIBRARY_DIR / name)
    save_mission(mission, tmp_path / "copy.yaml")
    assert load_mission(tmp_path / "copy.yaml") == mission


def test_loaded_numbers_are_floats_whatever_the_spelling(tmp_path: Path) -> None:
    mission = load_mission(write(tmp_path, BASE))  # BASE writes 50, not 50.0
    assert type(mission.flight.altitude_m) is float and type(mission.scenario.area.north_min_m) is float
    assert type(mission.scenario.targets[0].north_m) is float and type(mission.flight.max_steps) is int


def test_mission_to_dict_is_plain_yaml_data_and_reads_back() -> None:
    mission = mission_from_dict(BASE, Path("."))
    data = mission_to_dict(mission)
    assert yaml.safe_load(yaml.safe_dump(data)) == data  # safe_dump refuses anything but builtin types
    assert data["scenario"]["conditions"]["sea"] == "calm"
    assert mission_from_dict(data, Path(".")) == mission


def test_numpy_values_are_saved_as_builtin_numbers(tmp_path: Path) -> None:
    np = pytest.importorskip("numpy")
    scenario = Scenario(area=SearchArea(np.float64(-100), np.float64(100), -100.0, 100.0),
                        targets=(Target("boat", np.float64(10.5), np.float64(2.0), primary=True),), seed=np.int64(3))
    save_mission(Mission(scenario=scenario), tmp_path / "np.yaml")
    loaded = load_mission(tmp_path / "np.yaml")
    assert loaded.scenario == scenario and type(loaded.scenario.seed) is int


def test_save_is_atomic_and_leaves_no_temp_files(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "m.yaml"
    first = mission_from_dict(BASE, tmp_path)
    save_mission(first, path)
    save_mission(first, path)  # overwriting works
    assert [p.name for p in tmp_path.iterdir()] == ["m.yaml"]

    def failing_replace(src: Any, dst: Any) -> None:
        raise OSError("disk gone")

    monkeypatch.setattr(os, "replace", failing_replace)
    with pytest.raises(OSError, match="disk gone"):
        save_mission(mission_from_dict(changed(name="second"), tmp_path), path)
    assert [p.name for p in tmp_path.iterdir()] == ["m.yaml"]  # the temp file was removed
    assert load_mission(path) == first  # and the old file is untouched


finite = st.floats(min_value=-5000, max_value=5000, allow_nan=False).map(lambda x: round(x, 3))


@st.composite
def missions(draw: st.DrawFn) -> Mission:
    north_min, east_min = draw(finite), draw(finite)
    # >= 11 m, not 10: max - min can round to a hair under what was drawn, and SearchArea needs 10 m.
    area = SearchArea(north_min, north_min + draw(st.floats(11, 5000)), east_min, east_min + draw(st.floats(11, 5000)))

    def point() -> tuple[float, float]:
        return (draw(st.floats(area.north_min_m, area.north_max_m)), draw(st.floats(area.east_min_m, area.east_max_m)))

    targets = [Target(draw(st.sampled_from(CATEGORIES)), *point(), primary=(i == 0))
               for i in range(draw(st.integers(1, 5)))]
    start = point()
    scenario = Scenario(
        area=area, home=GeoPoint(draw(st.floats(-90, 90)), draw(st.floats(-180, 180)), draw(finite)),
        start_north_m=start[0], start_east_m=start[1], datum_north_m=draw(finite), datum_east_m=draw(finite),
        datum_sigma_m=draw(st.floats(0, 1e5)), targets=tuple(draw(st.permutations(targets))),
        obstacles=tuple(Obstacle(*point(), draw(st.floats(0.1, 1e5))) for _ in range(draw(st.integers(0, 3)))),
        conditions=Conditions(draw(st.sampled_from(SeaState)), draw(st.sampled_from(Weather)),
                              draw(st.sampled_from(TimeOfDay)), draw(st.floats(0.3, 1.0)), draw(st.floats(0, 1)),
                              draw(st.floats(-360, 360))),
        current_north_mps=draw(st.floats(-5, 5)), current_east_mps=draw(st.floats(-5, 5)),
        seed=draw(st.integers(0, 2**63)), name=draw(st.sampled_from(["", "hand-made", "seed 12"])))
    flight = FlightSettings(draw(st.floats(10, 120)), draw(st.floats(1, 20)), draw(st.floats(0.1, 10)),
                            draw(st.integers(1, 1000)), draw(st.integers(10, 100_000)), draw(st.floats(1, 100)))
    fence = draw(st.none() | st.just(SearchArea(area.north_min_m - 1, area.north_max_m + 1, area.east_min_m,
                                                area.east_max_m)))
    return Mission(scenario=scenario, flight=flight, name=draw(st.sampled_from(["m", "night search", "été"])),
                   geofence=fence)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(mission=missions())
def test_round_trip_property(tmp_path: Path, mission: Mission) -> None:
    save_mission(mission, tmp_path / "m.yaml")
    assert load_mission(tmp_path / "m.yaml") == mission
