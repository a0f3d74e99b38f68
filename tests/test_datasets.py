"""SAR datasets: the synthetic generator, the YOLO loader (SAR-2 layout), image -> scenario, ``hrlsac dataset``."""
from __future__ import annotations

import hashlib
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from missions.datasets import YoloDataset
from missions.image_scenarios import ImageScenarioConfig, scenario_from_item
from missions.yolo_labels import DatasetError, label_path_for
from missions.scenario import CATEGORIES
from missions.synthetic import make_synthetic_dataset, split_counts

HRLSAC = [sys.executable, "-m", "hrlsac_cli"]
PRIMARY = {"person", "swimmer", "life_jacket"}


@pytest.fixture(scope="module")
def synth20(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("synth") / "sar"
    make_synthetic_dataset(out, count=20, seed=7)
    return out


def read_labels(path: Path) -> list[tuple[int, float, float, float, float]]:
    rows = []
    for line in path.read_text().splitlines():
        fields = line.split()
        assert len(fields) == 5, f"{path}: {line!r}"
        rows.append((int(fields[0]), *map(float, fields[1:])))
    return rows


def tree_hashes(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


# -- the synthetic dataset -----------------------------------------------------------------------------------

def test_split_counts_are_exact():
    assert split_counts(200, (0.7, 0.2, 0.1)) == (140, 40, 20)
    assert split_counts(20, (0.7, 0.2, 0.1)) == (14, 4, 2)
    assert sum(split_counts(7, (0.7, 0.2, 0.1))) == 7
    with pytest.raises(ValueError, match="sum to 1"):
        split_counts(10, (0.5, 0.2, 0.1))


def test_synthetic_dataset_layout_labels_and_images(synth20):
    data = yaml.safe_load((synth20 / "data.yaml").read_text())
    assert data["nc"] == 6 and data["names"] == list(CATEGORIES)
    assert (data["train"], data["val"], data["test"]) == ("images/train", "images/val", "images/test")
    assert Path(data["path"]) == synth20.resolve()
    counts = {}
    for split in ("train", "val", "test"):
        images = sorted((synth20 / "images" / split).glob("*.png"))
        counts[split] = len(images)
        for image_path in images:
            image = cv2.imread(str(image_path), cv2.IMREAD_UNCHANGED)
            assert image.shape == (480, 640, 3)
            rows = read_labels(synth20 / "labels" / split / f"{image_path.stem}.txt")
            assert 1 <= len(rows) <= 6
            assert sum(CATEGORIES[c] in PRIMARY for c, *_ in rows) == 1  # exactly one primary candidate
            pixel_boxes = []
            for c, cx, cy, w, h in rows:
                assert 0 <= c < 6 and w > 0 and h > 0
                assert 0 <= cx - w / 2 and cx + w / 2 <= 1 + 1e-6 and 0 <= cy - h / 2 and cy + h / 2 <= 1 + 1e-6
                pixel_boxes.append(((cx - w / 2) * 640, (cy - h / 2) * 480, (cx + w / 2) * 640, (cy + h / 2) * 480))
            for i, a in enumerate(pixel_boxes):  # boxes do not overlap
                for b in pixel_boxes[i + 1:]:
                    assert a[2] <= b[0] + 1e-3 or b[2] <= a[0] + 1e-3 or a[3] <= b[1] + 1e-3 or b[3] <= a[1] + 1e-3
    assert counts == {"train": 14, "val": 4, "test": 2}
    assert not list(synth20.rglob("*.tmp"))


def test_synthetic_dataset_is_deterministic_per_seed(tmp_path):
    first = tree_hashes(make_synthetic_dataset(tmp_path / "a", count=5, seed=3).root)
    second = tree_hashes(make_synthetic_dataset(tmp_path / "b", count=5, seed=3).root)
    other = tree_hashes(make_synthetic_dataset(tmp_path / "c", count=5, seed=4).root)
    # data.yaml names its own (absolute) location; everything else must be byte-identical.
    assert {k: v for k, v in first.items() if k != "data.yaml"} == {k: v for k, v in second.items() if k != "data.yaml"}
    assert ((tmp_path / "a" / "data.yaml").read_text().replace(str((tmp_path / "a").resolve()), "X")
            == (tmp_path / "b" / "data.yaml").read_text().replace(str((tmp_path / "b").resolve()), "X"))
    assert all(first[k] != other[k] for k in first if k.endswith(".png"))
    # an image depends on (seed, index) only, not on how many images are made
    assert tree_hashes(make_synthetic_dataset(tmp_path / "d", count=10, seed=3).root)["images/train/synth_00000.png"] \
        == first["images/train/synth_00000.png"]


def test_synthetic_dataset_refuses_to_overwrite(tmp_path):
    out = tmp_path / "out"
    make_synthetic_dataset(out, count=3, seed=0)
    (out / "notes.txt").write_text("keep me")
    with pytest.raises(FileExistsError, match=str(out)):
        make_synthetic_dataset(out, count=3, seed=1)
    summary = make_synthetic_dataset(out, count=2, seed=1, overwrite=True)
    assert summary.images == {"train": 1, "val": 1, "test": 0}
    assert len(list((out / "images").rglob("*.png"))) == 2  # the old images are gone
    assert (out / "notes.txt").read_text() == "keep me"  # what the generator did not write stays


# -- the loader on the synthetic dataset ---------------------------------------------------------------------

def test_loader_reads_synthetic_dataset_and_makes_one_scenario_per_image(synth20):
    dataset = YoloDataset(synth20, strict=True)
    assert dataset.splits() == ["train", "val", "test"]
    assert [len(dataset.items(s)) for s in dataset.splits()] == [14, 4, 2]
    scenarios = dataset.scenarios("train", seed=5)
    assert len(scenarios) == 14 and dataset.stats.images_without_scenario["train"] == 0

    item, scenario = dataset.items("train")[0], scenarios[0]
    assert scenario.name == f"train/{item.stem}" and item.image_size == (640, 480)
    area = scenario.area  # 1,000 m x 750 m (4:3 like the image), home 50 m north of the southern edge
    assert (area.north_min_m, area.north_max_m, area.east_min_m, area.east_max_m) == (-50.0, 700.0, -500.0, 500.0)
    assert (scenario.start_north_m, scenario.start_east_m) == (0.0, 0.0)
    rows = read_labels(item.label_path)
    assert len(scenario.targets) == len(rows)
    c, cx, cy, w, h = rows[0]
    target = scenario.targets[0]
    assert target.category == CATEGORIES[c]
    assert target.north_m == pytest.approx(700.0 - cy * 750.0) and target.east_m == pytest.approx(-500.0 + cx * 1000.0)
    assert scenario.primary.category in PRIMARY
    assert area.contains(scenario.datum_north_m, scenario.datum_east_m) and 50 <= scenario.datum_sigma_m <= 120

    again = YoloDataset(synth20).scenarios("train", seed=5)
    assert again == scenarios
    assert YoloDataset(synth20).scenarios("train", seed=6) != scenarios


def test_scenario_conditions_cover_all_48_combinations(synth20):
    item = YoloDataset(synth20).items("train")[0]
    config = ImageScenarioConfig(height_m=750.0)
    seen = {(s.conditions.sea, s.conditions.weather, s.conditions.time_of_day)
            for s in (scenario_from_item(item, config, seed) for seed in range(1500))}
    assert len(seen) == 48


# -- a hand-written dataset laid out like a Roboflow / SAR-2 export -------------------------------------------

def write_image(path: Path, width: int = 640, height: int = 640) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), np.full((height, width, 3), 90, np.uint8))


@pytest.fixture
def sar2_like(tmp_path) -> Path:
    root = tmp_path / "SAR-2"
    root.mkdir()
    (root / "data.yaml").write_text("train: ../train/images\nval: ../valid/images\ntest: ../test/images\n"
                                    "nc: 4\nnames: ['human', 'boat', 'buoy', 'seagull']\n")
    labels = {
        "train/a": "0 0.5 0.25 0.1 0.2\n1 0.25 0.75 0.2 0.1\n3 0.9 0.9 0.05 0.05\n",
        "train/b": "2 0.5 0.5 0.1 0.1\n",             # no person: yields no scenario
        "valid/c": "0 0.1 0.1 0.05 0.05\n0 0.6 0.6 0.2 0.2\n1 0.5 0.96 0.02 0.02\n",
        "valid/d": "0 0.5 0.5 0.1 0.1\n1 0.5 x 0.1 0.1\n",   # line 2 is malformed
        "test/e": "",
    }
    for name, text in labels.items():
        split, stem = name.split("/")
        write_image(root / split / "images" / f"{stem}.jpg")
        (root / split / "labels").mkdir(parents=True, exist_ok=True)
        (root / split / "labels" / f"{stem}.txt").write_text(text)
    return root


def test_loader_reads_a_sar2_like_export_with_aliases_and_valid_folder(sar2_like):
    dataset = YoloDataset(sar2_like)
    assert dataset.splits() == ["train", "val", "test"]
    assert dataset.categories == {0: "person", 1: "boat", 2: "floating_object", 3: None}
    a, b = dataset.items("train")
    assert [(box.name, box.category) for box in a.boxes] == [("human", "person"), ("boat", "boat")]
    assert dataset.stats.unknown_classes == {"seagull": 1}
    assert label_path_for(a.image_path) == sar2_like / "train" / "labels" / "a.txt"

    assert [s.name for s in dataset.scenarios("train")] == ["train/a"]
    assert dataset.stats.images_without_scenario["train"] == 1

    c, d = dataset.items("valid")  # the Roboflow folder name works as a split name too
    assert len(d.boxes) == 1 and dataset.stats.skipped_lines == 1
    assert f"{d.label_path}:2: cy must be a number, got 'x'" in dataset.stats.problems
    scenario = scenario_from_item(c)
    assert scenario.primary.north_m == pytest.approx(1000 - 50 - 0.6 * 1000)  # square image: 1,000 m x 1,000 m
    assert scenario.primary.east_m == pytest.approx(100.0)  # the larger of the two people is the victim
    assert len(scenario.targets) == 3 and not scenario.obstacles

    summary = dataset.summary()
    assert summary.images == {"train": 2, "val": 2, "test": 1}
    assert summary.scenarios == {"train": 1, "val": 2, "test": 0}
    assert summary.boxes["person"] == 4 and summary.boxes["boat"] == 2 and summary.boxes["floating_object"] == 1


def test_strict_mode_names_file_and_line(sar2_like):
    dataset = YoloDataset(sar2_like, strict=True)
    dataset.items("train")
    with pytest.raises(DatasetError, match=r"valid/labels/d\.txt:2: cy must be a number"):
        dataset.items("val")


@pytest.mark.parametrize("line, message", [
    ("0 0.5 0.5 0.1", "expected 5 fields"),
    ("person 0.5 0.5 0.1 0.1", "class id must be an integer"),
    ("7 0.5 0.5 0.1 0.1", "class id 7 is out of range"),
    ("0 1.5 0.5 0.1 0.1", "cx must be in [0, 1]"),
    ("0 0.5 0.5 0 0.1", "w and h must be > 0"),
    ("0 0.5 0.5 nan 0.1", "w must be in [0, 1]"),
])
def test_malformed_label_lines_are_reported(tmp_path, line, message):
    write_image(tmp_path / "images" / "train" / "x.png", 64, 48)
    (tmp_path / "labels" / "train").mkdir(parents=True)
    (tmp_path / "labels" / "train" / "x.txt").write_text(f"0 0.5 0.5 0.1 0.1\n\n{line}\n")
    with pytest.raises(DatasetError) as error:
        YoloDataset(tmp_path, names=["person"], strict=True).items("train")
    assert str(error.value).startswith(f"{tmp_path / 'labels' / 'train' / 'x.txt'}:3: {message}")
    lenient = YoloDataset(tmp_path, names=["person"])
    assert len(lenient.items("train")[0].boxes) == 1 and lenient.stats.skipped_lines == 1


def test_obstacle_classes_and_class_map(sar2_like):
    dataset = YoloDataset(sar2_like, obstacle_classes=["boat"], class_map={"seagull": "debris"})
    a = dataset.items("train")[0]
    assert [box.obstacle for box in a.boxes] == [False, True, False]
    assert not dataset.stats.unknown_classes
    scenario = scenario_from_item(a, ImageScenarioConfig(height_m=1000.0))
    assert [t.category for t in scenario.targets] == ["person", "debris"]
    (obstacle,) = scenario.obstacles
    assert (obstacle.north_m, obstacle.east_m) == pytest.approx((950 - 750, -250))
    assert obstacle.radius_m == pytest.approx(0.5 * np.hypot(200, 100))
    # valid/c's boat (20 m x 20 m, radius 14 m) lies 10 m north of the start point: it is left out
    c = dataset.items("val")[0]
    assert not scenario_from_item(c).obstacles
    with pytest.raises(ValueError, match="class_map"):
        YoloDataset(sar2_like, class_map={"seagull": "bird"})


def test_folder_layout_without_data_yaml_needs_names(tmp_path):
    write_image(tmp_path / "images" / "valid" / "x.png", 64, 48)
    with pytest.raises(DatasetError, match="no class names"):
        YoloDataset(tmp_path)
    (tmp_path / "classes.txt").write_text("Person\nLife-Jacket\n")
    dataset = YoloDataset(tmp_path)
    assert dataset.splits() == ["val"] and dataset.categories == {0: "person", 1: "life_jacket"}
    assert dataset.items("val")[0].boxes == ()


def test_malformed_data_yaml_is_a_clear_error(tmp_path):
    (tmp_path / "data.yaml").write_text("train: [unclosed\n")
    with pytest.raises(DatasetError, match="cannot read data.yaml"):
        YoloDataset(tmp_path)
    (tmp_path / "data.yaml").write_text("train: images/train\nnames: [a, b]\n")
    with pytest.raises(DatasetError, match="train: images/train not found"):
        YoloDataset(tmp_path)
    (tmp_path / "images" / "train").mkdir(parents=True)
    (tmp_path / "data.yaml").write_text("train: images/train\nnc: 3\nnames: [a, b]\n")
    with pytest.raises(DatasetError, match="nc is 3 but names lists 2 classes"):
        YoloDataset(tmp_path)


# -- hrlsac dataset ------------------------------------------------------------------------------------------

def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([*HRLSAC, "dataset", *args], capture_output=True, text=True, timeout=120)


def test_cli_synth_then_info(tmp_path):
    out = tmp_path / "synth"
    result = run("synth", str(out), "--count", "10", "--seed", "2")
    assert result.returncode == 0, result.stderr
    assert "10/10 images" in result.stdout
    assert "images: train 7, val 2, test 1" in result.stdout
    assert f"data.yaml: {out / 'data.yaml'}" in result.stdout

    again = run("synth", str(out), "--count", "10")
    assert again.returncode == 2 and "is not empty" in again.stderr
    assert len(again.stderr.strip().splitlines()) == 1 and "Traceback" not in again.stderr
    assert run("synth", str(out), "--count", "4", "--overwrite").returncode == 0

    info = run("info", str(out))
    assert info.returncode == 0, info.stderr
    assert "total        4          4" in info.stdout
    assert "0 malformed label line(s)" in info.stdout


def test_cli_info_on_a_sar2_like_export(sar2_like):
    info = run("info", str(sar2_like), "--obstacle-classes", "boat")
    assert info.returncode == 0, info.stderr
    assert "0 human -> person; 1 boat -> obstacle; 2 buoy -> floating_object; 3 seagull -> unmapped" in info.stdout
    assert "1 malformed label line(s); 1 box(es) of unmapped classes (seagull 1)" in info.stdout
    strict = run("info", str(sar2_like), "--strict")
    assert strict.returncode == 2 and "d.txt:2: cy must be a number" in strict.stderr
    assert len(strict.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("make", ["missing", "bad_yaml"])
def test_cli_bad_input_is_a_one_line_error(tmp_path, make):
    root = tmp_path / "nowhere"
    if make == "bad_yaml":
        root.mkdir()
        (root / "data.yaml").write_text("names: {zero: a}\ntrain: .\n")
    result = run("info", str(root))
    assert result.returncode == 2
    assert result.stderr.startswith("hrlsac dataset info: error: ") and str(root) in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and "Traceback" not in result.stderr
