"""YOLO-format search-and-rescue datasets (laid out like SAR-2) and the scenarios they describe.

Layouts that are understood (``root`` is the dataset folder):

* ``root/data.yaml`` in YOLOv5 style: ``path`` (optional), ``train``/``val``/``test`` (a folder of images,
  a ``.txt`` list of image paths, or a list of either), ``nc`` (optional) and ``names`` (a list, or a
  dict ``{id: name}``). Relative entries are resolved against ``path`` (when it exists) and then against
  the folder of data.yaml. Roboflow exports write ``../train/images``; when such an entry does not exist,
  the leading ``../`` parts are dropped and it is tried again relative to data.yaml.
* Without data.yaml: ``images/{train,val,test}`` or ``{train,val,test}/images``; the class names then come
  from ``names=`` or a ``classes.txt`` in the root.

``valid`` and ``validation`` are accepted as names of the validation split, which is always called
``val`` here. Label files follow the YOLO convention: the last ``images`` folder of an image's path is
replaced by ``labels`` and the suffix by ``.txt`` (``images/train/a.jpg`` -> ``labels/train/a.txt``); an
image without a label file has no boxes. A label line is ``class cx cy w h`` with the box centre and size
normalised to [0, 1] by the image's width and height.

Class names are mapped to the six categories of :data:`missions.scenario.CATEGORIES` by name through
:data:`CLASS_ALIASES` (case, ``-``, ``_`` and repeated spaces do not matter), which ``class_map`` can
extend or override. Boxes of unmapped classes are skipped and counted. Names listed in
``obstacle_classes`` become circular danger zones (:class:`~missions.scenario.Obstacle`) instead of targets.
"""
from __future__ import annotations

import math
import re
import zlib
from collections import Counter
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Collection, Iterable, Mapping

import numpy as np
import yaml

from missions.geodesy import GeoPoint
from missions.scenario import (CATEGORIES, Conditions, Obstacle, Scenario, SearchArea, SeaState, Target, TimeOfDay,
                               Weather)
from missions.validation import brief

SPLITS: tuple[str, ...] = ("train", "val", "test")
"""Split names, in reporting order."""

SPLIT_ALIASES: dict[str, str] = {"train": "train", "val": "val", "valid": "val", "validation": "val", "test": "test"}
"""Folder / data.yaml key -> split name (Roboflow exports call the validation split ``valid``)."""

IMAGE_SUFFIXES = frozenset({".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp"})

PRIMARY_CATEGORIES: tuple[str, ...] = ("person", "swimmer", "life_jacket")
"""Categories that can be the victim a scenario is about (the primary target)."""

CLASS_ALIASES: dict[str, str] = {
    **dict.fromkeys(("person", "persons", "people", "human", "humans"), "person"),
    **dict.fromkeys(("swimmer", "swimmers"), "swimmer"),
    **dict.fromkeys(("life jacket", "life jackets", "lifejacket", "lifejackets", "life vest", "lifevest"),
                    "life_jacket"),
    **dict.fromkeys(("boat", "boats", "ship", "ships", "vessel", "vessels"), "boat"),
    **dict.fromkeys(("debris", "wreckage"), "debris"),
    **dict.fromkeys(("floating object", "floating objects", "floatingobject", "buoy", "buoys"), "floating_object"),
}
"""Normalised dataset class name (see :func:`normalise_class_name`) -> one of CATEGORIES."""

MAX_PROBLEMS_KEPT = 20  # problem messages remembered for reports; the counts are always complete


class DatasetError(ValueError):
    """A dataset cannot be read: a missing folder, a malformed data.yaml or (in strict mode) a bad label line."""


def normalise_class_name(name: str) -> str:
    """``"Life-Jacket"`` -> ``"life jacket"``: lower case, ``-``/``_`` as spaces, single spaces."""
    return re.sub(r"[\s_\-]+", " ", str(name)).strip().lower()


@dataclass(frozen=True)
class Box:
    """One labelled box, normalised to the image: centre (cx, cy) and size (w, h) in [0, 1]."""

    class_id: int
    name: str
    """The dataset's own class name."""
    cx: float
    cy: float
    w: float
    h: float
    category: str | None = None
    """The box's category in CATEGORIES; None only for an obstacle class outside them."""
    obstacle: bool = False
    """True when the class is one of the dataset's ``obstacle_classes`` (a danger zone, not a target)."""

    @property
    def area(self) -> float:
        return self.w * self.h


@dataclass(frozen=True)
class YoloItem:
    """One image of a split with its (valid, mapped) boxes."""

    split: str
    image_path: Path
    label_path: Path
    boxes: tuple[Box, ...] = ()

    @property
    def stem(self) -> str:
        return self.image_path.stem

    @property
    def targets(self) -> tuple[Box, ...]:
        return tuple(b for b in self.boxes if not b.obstacle)

    @property
    def obstacles(self) -> tuple[Box, ...]:
        return tuple(b for b in self.boxes if b.obstacle)

    def primary_box(self) -> Box | None:
        """The victim: the largest person/swimmer/life_jacket box (ties: the first in the label file).

        The largest box is chosen because it is the most clearly seen candidate, and a choice by area does
        not depend on the order in which an annotation tool happened to write the lines.
        """
        candidates = [b for b in self.targets if b.category in PRIMARY_CATEGORIES]
        return max(candidates, key=lambda b: b.area) if candidates else None  # max keeps the first of ties

    @cached_property
    def image_size(self) -> tuple[int, int]:
        """(width, height) in pixels; read from the image file (with OpenCV) the first time it is asked for."""
        import cv2  # only here: loading labels must not need an image library

        image = cv2.imread(str(self.image_path), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise DatasetError(f"{self.image_path}: cannot read the image")
        return int(image.shape[1]), int(image.shape[0])


@dataclass
class LoadStats:
    """What a lenient load left out (strict loads raise instead of skipping lines)."""

    skipped_lines: int = 0
    """Malformed label lines that were skipped."""
    problems: list[str] = field(default_factory=list)
    """The first MAX_PROBLEMS_KEPT problems, one line each, naming file and line."""
    unknown_classes: Counter = field(default_factory=Counter)
    """Dataset class name -> number of boxes skipped because the class maps to no category."""
    images_without_scenario: dict[str, int] = field(default_factory=dict)
    """Split -> images the last :meth:`YoloDataset.scenarios` call skipped (no usable primary target)."""
    missing_images: int = 0
    """Entries of a ``.txt`` image list whose file does not exist (left out of the split)."""
    orphan_labels: int = 0
    """Label files beside a split's image folder with no image of that name (their boxes are unusable)."""

    def problem(self, message: str, skipped_line: bool = True) -> None:
        """Record a problem; ``skipped_line`` counts it as a skipped label line."""
        self.skipped_lines += int(skipped_line)
        if len(self.problems) < MAX_PROBLEMS_KEPT:
            self.problems.append(message)


@dataclass
class DatasetSummary:
    """Counts that describe a dataset: what ``hrlsac dataset synth`` wrote or ``hrlsac dataset info`` read."""

    root: Path
    images: dict[str, int] = field(default_factory=dict)
    """Split -> number of images."""
    boxes: dict[str, int] = field(default_factory=dict)
    """Category -> number of target boxes (all splits)."""
    obstacles: int = 0
    """Boxes of obstacle classes (all splits)."""
    scenarios: dict[str, int] = field(default_factory=dict)
    """Split -> images with a primary candidate, i.e. images that yield a scenario."""
    skipped_lines: int = 0
    unknown_classes: dict[str, int] = field(default_factory=dict)
    missing_images: int = 0
    """Listed images that do not exist (see LoadStats)."""
    orphan_labels: int = 0
    """Label files without an image (see LoadStats)."""
    problems: list[str] = field(default_factory=list)
    seconds: float = 0.0
    """How long making or reading the dataset took."""

    @property
    def data_yaml(self) -> Path:
        return self.root / "data.yaml"


def _int_field(text: str) -> int | None:
    try:
        return int(text)
    except ValueError:
        return None


def parse_label_line(text: str, class_ids: Collection[int], where: str) -> tuple[int, float, float, float, float]:
    """``"2 0.5 0.5 0.1 0.2"`` -> (2, 0.5, 0.5, 0.1, 0.2); raises DatasetError naming ``where`` (file:line)."""
    fields = text.split()
    if len(fields) != 5:
        raise DatasetError(f"{where}: expected 5 fields 'class cx cy w h', got {len(fields)}: {brief(text.strip())}")
    class_id = _int_field(fields[0])
    if class_id is None:
        raise DatasetError(f"{where}: class id must be an integer, got {brief(fields[0])}")
    if class_id not in class_ids:
        ids = sorted(class_ids)
        raise DatasetError(f"{where}: class id {class_id} is out of range (the dataset has ids "
                           f"{', '.join(map(str, ids)) if len(ids) <= 10 else f'{ids[0]}-{ids[-1]}'})")
    values = []
    for label, raw in zip(("cx", "cy", "w", "h"), fields[1:]):
        try:
            value = float(raw)
        except ValueError:
            raise DatasetError(f"{where}: {label} must be a number, got {brief(raw)}") from None
        if not (math.isfinite(value) and 0.0 <= value <= 1.0):
            raise DatasetError(f"{where}: {label} must be in [0, 1] (normalised), got {brief(raw)}")
        values.append(value)
    cx, cy, w, h = values
    if w <= 0.0 or h <= 0.0:
        raise DatasetError(f"{where}: w and h must be > 0, got w={brief(fields[3])} h={brief(fields[4])}")
    return class_id, cx, cy, w, h


def label_path_for(image_path: Path) -> Path:
    """The YOLO label file of an image: the last ``images`` folder becomes ``labels``, the suffix ``.txt``."""
    parts = list(image_path.parts)
    for i in range(len(parts) - 2, -1, -1):
        if parts[i] == "images":
            parts[i] = "labels"
            break
    return Path(*parts).with_suffix(".txt")


class YoloDataset:
    """A YOLO-format dataset (see the module notes for the layouts and the class-name mapping).

    Args:
        root: the dataset folder.
        names: class names by id; overrides data.yaml's ``names``.
        class_map: extra or overriding aliases, dataset class name -> category in CATEGORIES, or None to
            ignore the class.
        obstacle_classes: class names (dataset names or categories) whose boxes become obstacles.
        strict: raise DatasetError on the first malformed label line instead of skipping it.
    """

    def __init__(self, root: str | Path, names: Iterable[str] | Mapping[int, str] | None = None, *,
                 class_map: Mapping[str, str | None] | None = None, obstacle_classes: Iterable[str] = (),
                 strict: bool = False) -> None:
        self.root = Path(root)
        if not self.root.is_dir():
            raise DatasetError(f"{self.root}: no such dataset directory")
        self.strict = strict
        self.stats = LoadStats()
        self.yaml_path: Path | None = next((p for p in (self.root / "data.yaml", self.root / "data.yml")
                                            if p.is_file()), None)
        config = self._read_yaml() if self.yaml_path else {}
        self.names: dict[int, str] = self._class_names(names, config)
        self._sources: dict[str, list[Path]] = self._split_sources(config)
        self._items: dict[str, list[YoloItem]] = {}
        self._missing_counted: set[str] = set()

        aliases = dict(CLASS_ALIASES)
        for name, category in (class_map or {}).items():
            if category is not None and category not in CATEGORIES:
                raise ValueError(f"class_map[{name!r}] must be one of {', '.join(CATEGORIES)} or None, "
                                 f"got {category!r}")
            aliases[normalise_class_name(name)] = category
        obstacle_names = {normalise_class_name(n) for n in obstacle_classes}
        self.categories: dict[int, str | None] = {}
        """Class id -> category (None: unmapped)."""
        self.obstacle_ids: set[int] = set()
        for class_id, name in self.names.items():
            category = aliases.get(normalise_class_name(name))
            self.categories[class_id] = category
            if normalise_class_name(name) in obstacle_names or (
                    category is not None and normalise_class_name(category) in obstacle_names):
                self.obstacle_ids.add(class_id)

    # -- layout -------------------------------------------------------------------------------------------

    def _read_yaml(self) -> dict:
        assert self.yaml_path is not None
        try:
            config = yaml.safe_load(self.yaml_path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
            detail = str(exc).replace("\n", " ")
            raise DatasetError(f"{self.yaml_path}: cannot read data.yaml: {detail}") from None
        if not isinstance(config, dict):
            raise DatasetError(f"{self.yaml_path}: expected a mapping with train/val/test and names, "
                               f"got {type(config).__name__}")
        return config

    def _class_names(self, names, config: dict) -> dict[int, str]:
        where, from_yaml = "names=", False
        if names is None and "names" in config:
            names, where, from_yaml = config["names"], f"{self.yaml_path}: names", True
        elif names is None and (self.root / "classes.txt").is_file():
            where = f"{self.root / 'classes.txt'}"
            names = [line.strip() for line in _read_text(self.root / "classes.txt").splitlines() if line.strip()]
        if names is None:
            raise DatasetError(f"{self.root}: no class names (no data.yaml with names, no classes.txt, no names=)")
        if isinstance(names, Mapping):
            table = {}
            for key, value in names.items():
                if isinstance(key, bool) or not isinstance(key, int) or key < 0:
                    raise DatasetError(f"{where}: keys must be class ids (integers >= 0), got {key!r}")
                table[key] = str(value)
        elif isinstance(names, (list, tuple)):
            table = {i: str(n) for i, n in enumerate(names)}
        else:
            raise DatasetError(f"{where}: expected a list or an {{id: name}} mapping, got {type(names).__name__}")
        if not table:
            raise DatasetError(f"{where}: no class names")
        nc = config.get("nc")
        if from_yaml and nc is not None and nc != len(table):
            raise DatasetError(f"{self.yaml_path}: nc is {nc!r} but names lists {len(table)} classes")
        return table

    def _resolve(self, key: str, entry: object, bases: list[Path]) -> Path:
        if not isinstance(entry, str) or not entry.strip():
            raise DatasetError(f"{self.yaml_path}: {key}: expected a path, got {entry!r}")
        path = Path(entry.strip())
        candidates = [path] if path.is_absolute() else [base / path for base in bases]
        parts = path.parts
        while parts and parts[0] == "..":  # Roboflow writes ../train/images relative to a sibling yolov5 checkout
            parts = parts[1:]
        if parts and len(parts) < len(path.parts):
            candidates.append(self.root / Path(*parts))
        found = next((c for c in candidates if c.exists()), None)
        if found is None:
            raise DatasetError(f"{self.yaml_path}: {key}: {entry} not found (looked in "
                               f"{', '.join(str(c) for c in candidates)})")
        return found

    def _split_sources(self, config: dict) -> dict[str, list[Path]]:
        sources: dict[str, list[Path]] = {}
        if self.yaml_path is not None:
            bases = [self.root]
            if isinstance(config.get("path"), str) and config["path"].strip():
                given = Path(config["path"].strip())
                given = given if given.is_absolute() else self.root / given
                if given.is_dir():
                    bases.insert(0, given)
            for key, entry in config.items():
                if key not in SPLIT_ALIASES or entry is None:
                    continue
                entries = entry if isinstance(entry, list) else [entry]
                sources.setdefault(SPLIT_ALIASES[key], []).extend(self._resolve(key, e, bases) for e in entries)
            if not sources:
                raise DatasetError(f"{self.yaml_path}: no train, val or test entry")
            return sources
        for folder, split in SPLIT_ALIASES.items():
            for candidate in (self.root / "images" / folder, self.root / folder / "images"):
                if candidate.is_dir():
                    sources.setdefault(split, []).append(candidate)
        if not sources:
            raise DatasetError(f"{self.root}: no data.yaml and no images/train, images/val, images/test "
                               "(or train/images, valid/images, test/images) folders")
        return sources

    def splits(self) -> list[str]:
        """The splits present, in the order train, val, test."""
        return [s for s in SPLITS if s in self._sources]

    def image_paths(self, split: str) -> list[Path]:
        """The images of a split, sorted by path."""
        if split not in self._sources:
            raise DatasetError(f"{self.root}: no split {split!r} (splits: {', '.join(self.splits())})")
        images: list[Path] = []
        for source in self._sources[split]:
            if source.is_dir():
                images += [p for p in source.rglob("*") if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file()]
            elif source.suffix.lower() in IMAGE_SUFFIXES:
                images.append(source)
            else:  # a .txt list of images, relative to the list's folder
                listed = [source.parent / line.strip() for line in _read_text(source).splitlines() if line.strip()]
                for number, path in enumerate(listed, start=1):
                    if path.is_file():
                        images.append(path)
                    elif split not in self._missing_counted:  # image_paths may be asked twice; count once
                        self.stats.missing_images += 1
                        self.stats.problem(f"{source}:{number}: listed image {path} not found; left out",
                                           skipped_line=False)
        self._missing_counted.add(split)
        return sorted(set(images))

    def orphan_labels(self, split: str) -> list[Path]:
        """Label files in the label folders of a split's image folders that belong to no image of the split."""
        expected = {label_path_for(path) for path in self.image_paths(split)}
        folders = {label_path_for(source / "x.jpg").parent for source in self._sources.get(split, [])
                   if source.is_dir()}
        return sorted(label for folder in folders if folder.is_dir() for label in folder.rglob("*.txt")
                      if label not in expected)

    # -- labels -------------------------------------------------------------------------------------------

    def items(self, split: str) -> list[YoloItem]:
        """The images of a split with their boxes (parsed once, then cached)."""
        split = SPLIT_ALIASES.get(split, split)
        if split not in self._items:
            self._items[split] = [self._load_item(split, path) for path in self.image_paths(split)]
            for label in self.orphan_labels(split):
                self.stats.orphan_labels += 1
                self.stats.problem(f"{label}: label file without an image; ignored", skipped_line=False)
        return self._items[split]

    def _load_item(self, split: str, image_path: Path) -> YoloItem:
        label_path = label_path_for(image_path)
        boxes: list[Box] = []
        if label_path.is_file():
            try:
                lines = label_path.read_text(encoding="utf-8-sig").splitlines()  # -sig: a BOM is not part of the id
            except (OSError, UnicodeDecodeError) as exc:
                if self.strict:
                    raise DatasetError(f"{label_path}: cannot read: {exc}") from None
                self.stats.problem(f"{label_path}: cannot read: {exc}", skipped_line=False)
                lines = []
            for number, line in enumerate(lines, start=1):
                if not line.strip():
                    continue
                try:
                    class_id, cx, cy, w, h = parse_label_line(line, self.names, f"{label_path}:{number}")
                except DatasetError as exc:
                    if self.strict:
                        raise
                    self.stats.problem(str(exc))
                    continue
                name, category = self.names[class_id], self.categories[class_id]
                obstacle = class_id in self.obstacle_ids
                if category is None and not obstacle:
                    self.stats.unknown_classes[name] += 1
                    continue
                boxes.append(Box(class_id, name, cx, cy, w, h, category, obstacle))
        return YoloItem(split, image_path, label_path, tuple(boxes))

    # -- scenarios and summaries --------------------------------------------------------------------------

    def scenarios(self, split: str, config: ImageScenarioConfig | None = None, seed: int = 0) -> list[Scenario]:
        """One scenario per image with a usable primary target; the same seed gives the same scenarios.

        Each image gets its own seed derived from (seed, split, index), so a scenario does not change
        when other images are added or removed after it. Skipped images are counted in
        ``stats.images_without_scenario[split]``.
        """
        config = config or ImageScenarioConfig()
        split = SPLIT_ALIASES.get(split, split)
        result, skipped = [], 0
        for index, item in enumerate(self.items(split)):
            try:
                scenario = scenario_from_item(item, config, image_seed(seed, split, index))
            except DatasetError as exc:  # an unreadable image when the area's height comes from the image
                if self.strict:
                    raise
                self.stats.problem(str(exc), skipped_line=False)
                scenario = None
            if scenario is None:
                skipped += 1
            else:
                result.append(scenario)
        self.stats.images_without_scenario[split] = skipped
        return result

    def summary(self) -> DatasetSummary:
        """Counts over all splits (loads every label file; does not open images)."""
        summary = DatasetSummary(self.root, boxes={c: 0 for c in CATEGORIES})
        for split in self.splits():
            items = self.items(split)
            summary.images[split] = len(items)
            summary.scenarios[split] = sum(1 for item in items if item.primary_box() is not None)
            for item in items:
                for box in item.boxes:
                    if box.obstacle:
                        summary.obstacles += 1
                    else:
                        summary.boxes[box.category] += 1
        summary.skipped_lines = self.stats.skipped_lines
        summary.unknown_classes = dict(self.stats.unknown_classes)
        summary.missing_images, summary.orphan_labels = self.stats.missing_images, self.stats.orphan_labels
        summary.problems = list(self.stats.problems)
        return summary


def _read_text(path: Path) -> str:
    """A dataset's text file (classes.txt, an image list); unreadable or not UTF-8 is a DatasetError naming it."""
    try:
        return path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise DatasetError(f"{path}: cannot read: {exc}") from None


def image_seed(seed: int, split: str, index: int) -> int:
    """A per-image seed from the dataset seed, the split and the image's index in it."""
    return int(np.random.SeedSequence([seed, zlib.crc32(split.encode()), index]).generate_state(1)[0])


# -- images -> scenarios ------------------------------------------------------------------------------------

@dataclass(frozen=True)
class ImageScenarioConfig:
    """How an annotated image becomes a search scenario (the image is a top-down view of the search area)."""

    width_m: float = 1000.0
    """East-west extent of the area the image spans (m). Allowed [10, 100000]."""
    height_m: float | None = None
    """North-south extent (m); None keeps the image's aspect ratio (750 m for 640x480 images at 1,000 m),
    which needs the image size (read once per image). Allowed [10, 100000]."""
    south_margin_m: float = 50.0
    """How far home lies north of the area's southern edge (m): the area's north_min is -south_margin_m.
    Allowed [0, height]."""
    home: GeoPoint = field(default_factory=lambda: Scenario().home)
    """Geodetic home (origin of the local frame); the Scenario default."""
    min_obstacle_radius_m: float = 10.0
    """Smallest obstacle radius (m). Allowed [0.1, 10000]."""
    datum_sigma_m: tuple[float, float] = (50.0, 120.0)
    """Range of the datum uncertainty (m), drawn uniformly; the datum is the primary target's position plus
    an isotropic normal offset with that sigma. Allowed 0 <= low <= high <= 100000."""
    max_current_mps: float = 0.5
    """Sea currents are drawn with speeds uniform in [0, max_current_mps] (m/s). Allowed [0, 5]."""

    def __post_init__(self) -> None:
        def check(name: str, value: object, low: float, high: float) -> None:
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or not low <= value <= high:
                raise ValueError(f"ImageScenarioConfig.{name} must be in [{low:g}, {high:g}], got {value!r}")

        check("width_m", self.width_m, 10.0, 1e5)
        if self.height_m is not None:
            check("height_m", self.height_m, 10.0, 1e5)
            check("south_margin_m", self.south_margin_m, 0.0, self.height_m)
        else:
            check("south_margin_m", self.south_margin_m, 0.0, 1e5)
        check("min_obstacle_radius_m", self.min_obstacle_radius_m, 0.1, 1e4)
        check("max_current_mps", self.max_current_mps, 0.0, 5.0)
        low, high = self.datum_sigma_m
        check("datum_sigma_m[0]", low, 0.0, 1e5)
        check("datum_sigma_m[1]", high, low, 1e5)

    def area_for(self, item: YoloItem) -> SearchArea:
        """The search area an image spans: centred east-west on home, south edge south_margin_m south of it."""
        height = self.height_m
        if height is None:
            width_px, height_px = item.image_size
            height = self.width_m * height_px / width_px
        if self.south_margin_m > height:
            raise ValueError(f"ImageScenarioConfig.south_margin_m ({self.south_margin_m:g}) must not exceed the "
                             f"area's height ({height:g} m)")
        return SearchArea(north_min_m=-self.south_margin_m, north_max_m=height - self.south_margin_m,
                          east_min_m=-self.width_m / 2, east_max_m=self.width_m / 2)


def image_to_local(area: SearchArea, x: float, y: float) -> tuple[float, float]:
    """Normalised image coordinates -> (north_m, east_m): x grows east, y grows downwards, i.e. south."""
    return area.north_max_m - y * area.size_north_m, area.east_min_m + x * area.size_east_m


# Visibility ranges (fraction) by weather: fog and rain shorten how far the camera sees.
_VISIBILITY = {Weather.CLEAR: (0.8, 1.0), Weather.CLOUDY: (0.6, 1.0), Weather.RAINY: (0.4, 0.8),
               Weather.FOGGY: (0.3, 0.6)}
# Wind ranges (fraction of full scale) by sea state, so that a rough sea comes with a strong wind.
_WIND = {SeaState.CALM: (0.0, 0.35), SeaState.MODERATE: (0.2, 0.7), SeaState.ROUGH: (0.5, 1.0)}


def _draw_conditions(rng: np.random.Generator) -> Conditions:
    # Sea, weather and time of day are drawn independently and uniformly: all 48 combinations occur.
    sea = SeaState(int(rng.integers(len(SeaState))))
    weather = Weather(int(rng.integers(len(Weather))))
    time_of_day = TimeOfDay(int(rng.integers(len(TimeOfDay))))
    visibility = float(rng.uniform(*_VISIBILITY[weather]))
    wind = float(rng.uniform(*_WIND[sea]))
    return Conditions(sea, weather, time_of_day, round(visibility, 3), round(wind, 3),
                      round(float(rng.uniform(0.0, 360.0)), 1))


def scenario_from_item(item: YoloItem, config: ImageScenarioConfig = ImageScenarioConfig(),
                       seed: int = 0) -> Scenario | None:
    """The search scenario an annotated image describes, or None when it has no primary candidate.

    The image spans ``config``'s area (x -> east, y downwards -> south); home and the start are at the
    middle of the southern part, ``south_margin_m`` north of the edge. Every target box becomes a Target at
    the box centre; the primary is :meth:`YoloItem.primary_box`. Obstacle boxes become obstacles whose radius
    is half the box diagonal in metres (at least ``min_obstacle_radius_m``); an obstacle that would cover
    the start point is left out, since the drone could not take off. Images carry no weather labels, so
    the conditions, the sea current and the datum offset are drawn from ``numpy.random.default_rng(seed)``.
    """
    primary = item.primary_box()
    if primary is None:
        return None
    area = config.area_for(item)
    rng = np.random.default_rng(seed)
    targets = tuple(Target(b.category, *image_to_local(area, b.cx, b.cy), primary=b is primary)
                    for b in item.targets)
    obstacles = []
    for box in item.obstacles:
        north, east = image_to_local(area, box.cx, box.cy)
        radius = max(config.min_obstacle_radius_m, 0.5 * math.hypot(box.w * area.size_east_m,
                                                                    box.h * area.size_north_m))
        if math.hypot(north, east) > radius:
            obstacles.append(Obstacle(north, east, radius))
    conditions = _draw_conditions(rng)
    speed, heading = rng.uniform(0.0, config.max_current_mps), rng.uniform(0.0, 2 * math.pi)
    sigma = float(rng.uniform(*config.datum_sigma_m))
    offset_north, offset_east = rng.normal(0.0, sigma, size=2) if sigma > 0 else (0.0, 0.0)
    primary_target = next(t for t in targets if t.primary)
    datum_north = float(np.clip(primary_target.north_m + offset_north, area.north_min_m, area.north_max_m))
    datum_east = float(np.clip(primary_target.east_m + offset_east, area.east_min_m, area.east_max_m))
    return Scenario(area=area, home=config.home, start_north_m=0.0, start_east_m=0.0,
                    datum_north_m=datum_north, datum_east_m=datum_east, datum_sigma_m=sigma,
                    targets=targets, obstacles=tuple(obstacles), conditions=conditions,
                    current_north_mps=float(speed * math.cos(heading)),
                    current_east_mps=float(speed * math.sin(heading)),
                    seed=int(seed), name=f"{item.split}/{item.stem}")
