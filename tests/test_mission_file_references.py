"""Mission files' references instead of inline scenarios: generator references (the index -> seed wiring,
reproducible, frozen inline, drawing from SarSearch-v1) and dataset references (the root relative to the file, the
errors, the real loader); and SarSearch-v1's fields (endurance, forecast current)."""
from __future__ import annotations

import sys
import types
from pathlib import Path
from typing import Any

import pytest
import yaml
from mission_file_helpers import BASE, NEEDS_DATASETS, NEEDS_GENERATOR, changed, error_of, write

from missions.mission import Mission
from missions.mission_file import LIBRARY_DIR, MissionFileError, load_mission, mission_from_dict
from missions.mission_sections import GENERATOR_SPLITS
from missions.mission_writer import save_mission
from missions.scenario import Scenario, Target


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
