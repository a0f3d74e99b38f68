"""Mission files: bundled library, round trips, one-line errors with field paths, generator and dataset references."""
from __future__ import annotations

import copy
import math
import os
import sys
import textwrap
import types
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from missions.geodesy import GeoPoint
from missions.mission import FlightSettings, Mission
from missions.mission_file import LIBRARY_DIR, MissionFileError, load_mission, mission_from_dict
from missions.mission_sections import GENERATOR_SPLITS
from missions.mission_writer import mission_to_dict, save_mission
from missions.scenario import (CATEGORIES, Conditions, Obstacle, Scenario, SearchArea, SeaState, Target, TimeOfDay,
                               Weather)

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
                        "scenario.generator.split: 'tset' is not one of train, val, test; did you mean 'test'?"),
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


# ------------------------------------------------------------------------------------------------ generator

def fake_generator(monkeypatch: pytest.MonkeyPatch, calls: list[int]) -> None:
    """A stand-in missions.generator: tests our index -> seed wiring, whether or not the real one exists."""
    module = types.ModuleType("missions.generator")

    def scenario_seeds(split: str, count: int) -> list[int]:
        return [{"train": 0, "val": 1_000, "test": 2_000}[split] + i for i in range(count)]

    def generate_scenario(seed: int) -> Scenario:
        calls.append(seed)
        return Scenario(targets=(Target("person", 1.0, 2.0, primary=True),), seed=seed, name=f"generated {seed}")

    module.scenario_seeds, module.generate_scenario = scenario_seeds, generate_scenario
    monkeypatch.setitem(sys.modules, "missions.generator", module)


def test_generator_reference_wiring(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[int] = []
    fake_generator(monkeypatch, calls)
    assert load_mission(write(tmp_path, {"scenario": {"generator": {"split": "test", "index": 3}}})).scenario.seed \
        == 2_003
    assert load_mission(write(tmp_path, {"scenario": {"generator": {"seed": 42}}})).scenario.seed == 42
    assert calls == [2_003, 42]


def test_generator_reference_is_reproducible() -> None:
    generator = pytest.importorskip("missions.generator", reason=NEEDS_GENERATOR)
    path = LIBRARY_DIR / "generated_test_003.yaml"
    first, second = load_mission(path), load_mission(path)
    assert first == second
    assert first.scenario == generator.generate_scenario(generator.scenario_seeds("test", 4)[3])


def test_generator_splits_match_the_generator() -> None:
    generator = pytest.importorskip("missions.generator", reason=NEEDS_GENERATOR)
    assert GENERATOR_SPLITS == generator.SPLITS


def test_generated_mission_can_be_frozen_inline(tmp_path: Path) -> None:
    pytest.importorskip("missions.generator", reason=NEEDS_GENERATOR)
    mission = load_mission(LIBRARY_DIR / "generated_test_003.yaml")
    save_mission(mission, tmp_path / "frozen.yaml")
    assert "generator" not in (tmp_path / "frozen.yaml").read_text()
    assert load_mission(tmp_path / "frozen.yaml") == mission


# ------------------------------------------------------------------------------------------------ dataset

def fake_datasets(monkeypatch: pytest.MonkeyPatch, roots: list[Path]) -> None:
    """Stand-ins for missions.datasets, listing <root>/images/<split>/, and missions.image_scenarios, in which
    img_0041 has no victim (no scenario)."""
    module, scenarios = types.ModuleType("missions.datasets"), types.ModuleType("missions.image_scenarios")

    class YoloDataset:
        def __init__(self, root: Path) -> None:
            roots.append(Path(root))
            self.root = Path(root)

        def items(self, split: str) -> list[types.SimpleNamespace]:
            folder = self.root / "images" / split
            if not folder.is_dir():
                raise ValueError(f"no split {split!r}")
            return [types.SimpleNamespace(image_path=p) for p in sorted(folder.iterdir())]

    def scenario_from_item(item: Any, config: Any = None, seed: int = 0) -> Scenario | None:
        if item.image_path.stem == "img_0041":
            return None
        return Scenario(targets=(Target("person", 5.0, 5.0, primary=True),), seed=seed, name=item.image_path.stem)

    def image_seed(seed: int, split: str, index: int) -> int:  # any injective stand-in will do here
        return seed * 1000 + index

    module.YoloDataset, scenarios.scenario_from_item, scenarios.image_seed = YoloDataset, scenario_from_item, image_seed
    monkeypatch.setitem(sys.modules, "missions.datasets", module)
    monkeypatch.setitem(sys.modules, "missions.image_scenarios", scenarios)


@pytest.fixture
def dataset_layout(tmp_path: Path) -> Path:
    """A two-image YOLO dataset in <tmp>/datasets/sar2 (test split) and an empty <tmp>/missions/ for the file.

    img_0042 shows a person (the victim) and debris; img_0041 only a boat, so it yields no scenario.
    """
    cv2 = pytest.importorskip("cv2")
    np = pytest.importorskip("numpy")
    root = tmp_path / "datasets" / "sar2"
    labels = {"img_0041": "1 0.3 0.3 0.1 0.1\n", "img_0042": "0 0.5 0.4 0.05 0.05\n2 0.7 0.8 0.1 0.1\n"}
    for folder in ("images/test", "labels/test"):
        (root / folder).mkdir(parents=True)
    for stem, text in labels.items():
        assert cv2.imwrite(str(root / "images" / "test" / f"{stem}.png"), np.zeros((48, 64, 3), np.uint8))
        (root / "labels" / "test" / f"{stem}.txt").write_text(text)
    (root / "classes.txt").write_text("person\nboat\ndebris\n")
    (tmp_path / "missions").mkdir()
    return tmp_path


def dataset_mission(folder: Path, **spec: Any) -> Path:
    reference = {"root": "../datasets/sar2", "split": "test", "image": "img_0042", "seed": 5, **spec}
    return write(folder / "missions", {"scenario": {"dataset": reference}})


def test_dataset_root_is_relative_to_the_mission_file(dataset_layout: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    roots: list[Path] = []
    fake_datasets(monkeypatch, roots)
    monkeypatch.chdir(dataset_layout / "datasets")  # the working directory must not matter
    scenario = load_mission(dataset_mission(dataset_layout)).scenario
    assert roots == [(dataset_layout / "datasets" / "sar2").resolve()]
    assert (scenario.name, scenario.seed) == ("img_0042", 5 * 1000 + 1)  # image 1 of the split, stand-in seed
    assert load_mission(dataset_mission(dataset_layout, image="img_0042.png")).scenario.name == "img_0042"


def test_dataset_root_not_found_shows_the_resolved_folder(dataset_layout: Path) -> None:
    path = dataset_mission(dataset_layout, root="../datasets/sar3")
    missions_dir = (dataset_layout / "missions").resolve()
    assert str(error_of(path)) == (f"{path}: scenario.dataset.root: dataset folder not found: "
                                   f"{(dataset_layout / 'datasets' / 'sar3').resolve()} "
                                   f"('../datasets/sar3' is relative to {missions_dir})")


@pytest.mark.parametrize("spec, expected", [
    ({"image": "img_00422"}, "scenario.dataset.image: 'img_00422' not found in split 'test' of {root} (2 images); "
                             "did you mean 'img_0042'?"),
    ({"image": "img_0041"}, "scenario.dataset.image: 'img_0041' yields no scenario (no labelled object can be "
                            "the primary target)"),
    ({"split": "val"}, "scenario.dataset.split: cannot list split 'val': no split 'val'"),
    ({"seed": -2}, "scenario.dataset.seed: must be an integer >= 0, got -2"),
])
def test_dataset_errors(dataset_layout: Path, monkeypatch: pytest.MonkeyPatch, spec: dict[str, Any],
                        expected: str) -> None:
    fake_datasets(monkeypatch, [])
    path = dataset_mission(dataset_layout, **spec)
    root = (dataset_layout / "datasets" / "sar2").resolve()
    assert str(error_of(path)) == f"{path}: {expected.format(root=root)}"


def test_dataset_reference_with_the_real_loader(dataset_layout: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    datasets = pytest.importorskip("missions.datasets", reason=NEEDS_DATASETS)
    monkeypatch.chdir(dataset_layout / "datasets")
    dataset = datasets.YoloDataset(dataset_layout / "datasets" / "sar2")
    (expected,) = [s for s in dataset.scenarios("test", seed=5) if s.name.endswith("img_0042")]
    path = dataset_mission(dataset_layout)
    assert load_mission(path).scenario == expected  # the very scenario an evaluation on the split flies
    assert load_mission(path) == load_mission(path)
    assert "'img_0041' yields no scenario" in str(error_of(dataset_mission(dataset_layout, image="img_0041")))
    assert "scenario.dataset.split: cannot list split 'val'" in str(error_of(dataset_mission(dataset_layout,
                                                                                              split="val")))


# ------------------------------------------------------------------------------------------- SarSearch-v1 fields

def test_endurance_and_forecast_current_load_validate_and_round_trip(tmp_path: Path) -> None:
    current = {"north_mps": 0.1, "east_mps": 0.0, "forecast_north_mps": 0.15, "forecast_east_mps": -0.02}
    data = changed(scenario__endurance_s=750, scenario__current=current)
    mission = load_mission(write(tmp_path, data))
    s = mission.scenario
    assert (s.endurance_s, s.forecast_current_north_mps, s.forecast_current_east_mps) == (750.0, 0.15, -0.02)
    assert isinstance(s.endurance_s, float)
    save_mission(mission, tmp_path / "again.yaml")
    assert load_mission(tmp_path / "again.yaml") == mission
    plain = load_mission(write(tmp_path, BASE, "plain.yaml")).scenario  # both optional: unlimited, exact forecast
    assert plain.endurance_s is None and plain.forecast_current_north_mps is None
    assert "endurance_s" not in yaml.safe_load(_saved(tmp_path, plain))["scenario"]
    assert str(error_of(write(tmp_path, changed(scenario__endurance_s=5), "short.yaml"))).endswith(
        "scenario.endurance_s: must be a number in [10, 1e+06], got 5")
    bad = changed(scenario__current={"north_mps": 0.1, "forecast_north_mps": 9})
    assert "scenario.current.forecast_north_mps: must be a number in [-5, 5], got 9" in str(error_of(write(
        tmp_path, bad, "fast.yaml")))


def _saved(folder: Path, scenario: Scenario) -> str:
    save_mission(Mission(scenario=scenario), folder / "saved.yaml")
    return (folder / "saved.yaml").read_text()


def test_a_generator_reference_may_draw_from_sarsearch_v1() -> None:
    from missions.generator import TASK_V1, generate_scenario, scenario_seeds

    folder = Path(__file__).parent
    data = changed(scenario={"generator": {"split": "test", "index": 3, "task": "SarSearch-v1"}})
    mission = mission_from_dict(data, folder)
    assert mission.scenario == generate_scenario(scenario_seeds("test", 4)[3], TASK_V1)
    assert mission.scenario.endurance_s is not None
    with pytest.raises(MissionFileError, match="scenario.generator.task: 'SarSearch-v2' is not one of sarsearch-v0, "
                                               "sarsearch-v1"):
        mission_from_dict(changed(scenario={"generator": {"seed": 3, "task": "SarSearch-v2"}}), folder)
