"""YOLO-format search-and-rescue datasets (laid out like SAR-2): finding a layout's images, labels and class names.

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

The records a dataset is read into, and the label-line parser, are ``missions/yolo_labels.py``; how an
image becomes a search scenario is ``missions/image_scenarios.py``.
"""
from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from pathlib import Path

import yaml

from missions.image_scenarios import ImageScenarioConfig, image_seed, scenario_from_item
from missions.scenario import CATEGORIES, Scenario
from missions.yolo_labels import (SPLITS, Box, DatasetError, DatasetSummary, LoadStats, YoloItem, label_path_for,
                                  parse_label_line)

SPLIT_ALIASES: dict[str, str] = {"train": "train", "val": "val", "valid": "val", "validation": "val", "test": "test"}
"""Folder / data.yaml key -> split name (Roboflow exports call the validation split ``valid``)."""

IMAGE_SUFFIXES = frozenset({".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp"})

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


def normalise_class_name(name: str) -> str:
    """``"Life-Jacket"`` -> ``"life jacket"``: lower case, ``-``/``_`` as spaces, single spaces."""
    return re.sub(r"[\s_\-]+", " ", str(name)).strip().lower()


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
