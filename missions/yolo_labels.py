"""The records a YOLO-format dataset is read into (boxes, images, load counts, summaries) and its label lines.

A label line is ``class cx cy w h`` with the box centre and size normalised to [0, 1] by the image's width and
height; the label file of ``images/train/a.jpg`` is ``labels/train/a.txt`` (the last ``images`` folder of the
path becomes ``labels``, the suffix ``.txt``). ``missions.datasets.YoloDataset`` finds the files of a layout.
"""
from __future__ import annotations

import math
from collections import Counter
from collections.abc import Collection
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

from missions.validation import brief

SPLITS: tuple[str, ...] = ("train", "val", "test")
"""Split names, in reporting order."""

PRIMARY_CATEGORIES: tuple[str, ...] = ("person", "swimmer", "life_jacket")
"""Categories that can be the victim a scenario is about (the primary target)."""

MAX_PROBLEMS_KEPT = 20  # problem messages remembered for reports; the counts are always complete


class DatasetError(ValueError):
    """A dataset cannot be read: a missing folder, a malformed data.yaml or (in strict mode) a bad label line."""


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
