"""The paper's synthetic fallback dataset: procedurally drawn top-down maritime scenes in YOLO format.

``make_synthetic_dataset(out)`` writes ``out/images/{train,val,test}/*.png`` (640x480), the matching
``out/labels/.../*.txt`` (``class cx cy w h``, class ids = indices in CATEGORIES) and, last,
``out/data.yaml``, so that a dataset without data.yaml is recognisably unfinished.

Every image shows a sea surface (colour gradient, wave trains, noise, sun glint, sometimes haze or dim
light) with exactly one primary candidate (a person, swimmer or life jacket, the victim of the scenario)
and 0-5 other objects (boats, debris, floating objects); keeping the other objects out of the primary
categories makes the victim of every image unambiguous. Boxes lie inside the image and do not overlap;
a box encloses the object itself, not its wake or splash.

Each image is drawn from its own generator seeded with (seed, index), so an image does not depend on any
other, and the same seed writes byte-identical images and labels.
"""
from __future__ import annotations

import math
import os
import shutil
import time
from collections import Counter
from pathlib import Path
from typing import Callable

import cv2
import numpy as np
import yaml

from missions.scenario import CATEGORIES
from missions.yolo_labels import SPLITS, DatasetSummary

IMAGE_WIDTH, IMAGE_HEIGHT = 640, 480
PRIMARY_CHOICES = ("person", "swimmer", "life_jacket")
OTHER_CHOICES = ("boat", "debris", "floating_object")
MAX_OTHERS = 5
GAP_PX = 4  # free sea between the drawn extents (object plus wake/splash) of two objects

Progress = Callable[[int, int], None]
"""``progress(done, total)``, called after each image."""

# Pixel coordinates, normalised to [0, 1], for the background's gradients and waves (computed once).
_YY, _XX = np.mgrid[0:IMAGE_HEIGHT, 0:IMAGE_WIDTH].astype(np.float32)


# -- the sea ------------------------------------------------------------------------------------------------

def _sea(rng: np.random.Generator) -> np.ndarray:
    """A top-down sea surface, float32 BGR in 0..255."""
    deep = np.array([rng.uniform(75, 120), rng.uniform(45, 85), rng.uniform(10, 35)], np.float32)
    shallow = deep + np.array([rng.uniform(15, 45), rng.uniform(25, 60), rng.uniform(5, 25)], np.float32)
    angle = rng.uniform(0.0, 2 * math.pi)
    ramp = _XX * math.cos(angle) + _YY * math.sin(angle)
    ramp = (ramp - ramp.min()) / (ramp.max() - ramp.min())
    image = deep + ramp[..., None] * (shallow - deep)

    # Wave trains travel roughly one way (the wind's), with a few crossing components.
    direction = rng.uniform(0.0, 2 * math.pi)
    waves = np.zeros_like(_XX)
    for _ in range(4):
        theta = direction + rng.normal(0.0, 0.35)
        wavelength = rng.uniform(10.0, 45.0)
        k = 2 * math.pi / wavelength
        waves += rng.uniform(0.4, 1.0) * np.sin(k * (_XX * math.cos(theta) + _YY * math.sin(theta))
                                                + rng.uniform(0.0, 2 * math.pi))
    swell = cv2.resize(rng.standard_normal((IMAGE_HEIGHT // 32 + 2, IMAGE_WIDTH // 32 + 2), dtype=np.float32),
                       (IMAGE_WIDTH, IMAGE_HEIGHT), interpolation=cv2.INTER_CUBIC)
    chop = cv2.resize(rng.standard_normal((IMAGE_HEIGHT // 6, IMAGE_WIDTH // 6), dtype=np.float32),
                      (IMAGE_WIDTH, IMAGE_HEIGHT), interpolation=cv2.INTER_LINEAR)
    roughness = rng.uniform(2.0, 7.0)
    texture = roughness * (waves + 0.8 * chop) + 6.0 * swell
    image += texture[..., None] * np.array([0.8, 0.9, 1.0], np.float32)

    # Sun glint: sparse bright specks on the wave crests facing the sun.
    crest = texture > np.quantile(texture, rng.uniform(0.97, 0.995))
    specks = (crest & (rng.random(crest.shape) < rng.uniform(0.2, 0.6))).astype(np.float32)
    image += cv2.GaussianBlur(specks, (3, 3), 0)[..., None] * rng.uniform(60.0, 140.0)
    return image


def _light(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Light and air over the whole scene: brightness, a warm dawn/dusk tint, sometimes haze."""
    image = image * rng.uniform(0.6, 1.15)
    if rng.random() < 0.3:
        image *= np.array([0.85, 0.95, 1.12], np.float32)
    if rng.random() < 0.25:
        haze = rng.uniform(0.1, 0.4)
        image = image * (1.0 - haze) + 185.0 * haze
    image += rng.standard_normal(image.shape[:2], dtype=np.float32)[..., None] * 1.5
    return np.clip(image, 0, 255).astype(np.uint8)


# -- objects ------------------------------------------------------------------------------------------------

FOAM = (225, 230, 230)  # BGR of white water


class _Sprite:
    """An object drawn on its own small canvas: the body (opaque, the labelled part) and foam around it.

    Foam (wake, splash, ripples) is white water of varying opacity with soft edges; the body is drawn
    over it and alone decides the bounding box.
    """

    def __init__(self, radius_px: float, angle: float):
        size = int(2 * radius_px) + 8
        self.colour = np.full((size, size, 3), FOAM, np.uint8)
        self.foam = np.zeros((size, size), np.uint8)
        self.body = np.zeros((size, size), np.uint8)
        self.centre = size / 2.0
        self.cos, self.sin = math.cos(angle), math.sin(angle)
        self.angle_deg = math.degrees(angle)

    def xy(self, u: float, v: float) -> tuple[int, int]:
        """Object frame (u along its length, v across) -> canvas pixel."""
        return (round(self.centre + u * self.cos - v * self.sin), round(self.centre + u * self.sin + v * self.cos))

    def _draw(self, draw: Callable[[np.ndarray, object], None], colour: tuple[int, int, int] | None,
              foam: int) -> None:
        if colour is None:
            draw(self.foam, foam)
        else:
            draw(self.colour, colour)
            draw(self.body, 255)

    def polygon(self, points_uv, colour: tuple[int, int, int] | None = None, foam: int = 0) -> None:
        """A filled polygon: body in ``colour``, or foam of opacity ``foam`` (0-255) when colour is None."""
        pts = np.array([self.xy(u, v) for u, v in points_uv], np.int32)
        self._draw(lambda layer, value: cv2.fillPoly(layer, [pts], value), colour, foam)

    def ellipse(self, u: float, v: float, half_length: float, half_width: float,
                colour: tuple[int, int, int] | None = None, foam: int = 0) -> None:
        """A filled ellipse centred at (u, v), its axes along and across the object."""
        axes = (max(1, round(half_length)), max(1, round(half_width)))
        self._draw(lambda layer, value: cv2.ellipse(layer, self.xy(u, v), axes, self.angle_deg, 0, 360, value, -1),
                   colour, foam)

    def line(self, a_uv, b_uv, colour: tuple[int, int, int], thickness: int) -> None:
        """A body line (arms, straps)."""
        self._draw(lambda layer, value: cv2.line(layer, self.xy(*a_uv), self.xy(*b_uv), value, thickness),
                   colour, 0)

    def crop(self) -> tuple[np.ndarray, np.ndarray, tuple[int, int, int, int]]:
        """(colour, opacity) cropped to what was drawn, and the body's box (x, y, w, h) inside the crop."""
        alpha = np.maximum(cv2.GaussianBlur(self.foam, (5, 5), 0), self.body)
        x, y, w, h = cv2.boundingRect(alpha)
        bx, by, bw, bh = cv2.boundingRect(self.body[y:y + h, x:x + w])
        return self.colour[y:y + h, x:x + w], alpha[y:y + h, x:x + w], (bx, by, bw, bh)


def _pick(rng: np.random.Generator, palette: list[tuple[int, int, int]]) -> tuple[int, int, int]:
    return palette[int(rng.integers(len(palette)))]


CLOTHES = [(40, 40, 200), (30, 30, 30), (170, 90, 30), (30, 140, 250), (235, 235, 235), (60, 170, 60)]
HAIR_SKIN = [(40, 60, 90), (25, 25, 35), (140, 170, 215), (70, 100, 150)]


def _person(rng: np.random.Generator) -> _Sprite:
    """Seen from above in the water: head and shoulders inside a ring of ripples."""
    width = rng.uniform(14.0, 26.0)
    sprite = _Sprite(0.8 * width, rng.uniform(0.0, 2 * math.pi))
    sprite.ellipse(0, 0, 0.78 * width, 0.6 * width, foam=70)
    sprite.ellipse(0, 0, 0.25 * width, 0.5 * width, _pick(rng, CLOTHES))  # shoulders across the body
    sprite.ellipse(0.05 * width, 0, 0.19 * width, 0.19 * width, _pick(rng, HAIR_SKIN))
    return sprite


def _swimmer(rng: np.random.Generator) -> _Sprite:
    """An elongated body with a head at one end, arms stroking forward, splashes around."""
    length = rng.uniform(26.0, 46.0)
    width = length * rng.uniform(0.22, 0.3)
    sprite = _Sprite(0.9 * length, rng.uniform(0.0, 2 * math.pi))
    sprite.ellipse(0, 0, 0.65 * length, 0.45 * length, foam=50)
    for _ in range(int(rng.integers(8, 18))):
        u = rng.choice([-0.5, 0.5]) * length + rng.normal(0.0, 0.12 * length)
        v = rng.normal(0.0, 0.5 * width)
        radius = rng.uniform(1.5, 4.0)
        sprite.ellipse(u, v, radius, radius, foam=int(rng.integers(110, 200)))
    sprite.ellipse(0, 0, 0.5 * length, 0.5 * width, _pick(rng, CLOTHES))
    side = rng.choice([-1.0, 1.0])
    sprite.line((0.25 * length, side * 0.4 * width), (0.55 * length, side * 0.9 * width), _pick(rng, HAIR_SKIN), 2)
    sprite.ellipse(0.5 * length, 0, 0.55 * width, 0.55 * width, _pick(rng, [(20, 220, 250), (40, 40, 220),
                                                                        (235, 235, 235), (25, 25, 35)]))
    return sprite


def _rounded_rect(half_length: float, half_width: float, radius: float) -> list[tuple[float, float]]:
    """Outline of a rectangle with rounded corners as (u, v) points."""
    points = []
    for su, sv, start in ((1, 1, 0), (-1, 1, 90), (-1, -1, 180), (1, -1, 270)):  # corner side, arc start angle
        cu, cv = su * (half_length - radius), sv * (half_width - radius)
        for step in range(5):
            a = math.radians(start + 22.5 * step)
            points.append((cu + radius * math.cos(a), cv + radius * math.sin(a)))
    return points


def _life_jacket(rng: np.random.Generator) -> _Sprite:
    """An orange rounded rectangle with a reflective stripe and a dark collar opening."""
    length = rng.uniform(14.0, 26.0)
    width = length * rng.uniform(0.65, 0.9)
    sprite = _Sprite(0.75 * length, rng.uniform(0.0, 2 * math.pi))
    sprite.ellipse(0, 0, 0.7 * length, 0.6 * width, foam=55)
    orange = (int(rng.integers(0, 30)), int(rng.integers(100, 160)), int(rng.integers(235, 256)))
    sprite.polygon(_rounded_rect(length / 2, width / 2, 0.25 * min(length, width)), orange)
    sprite.line((-0.1 * length, -0.45 * width), (-0.1 * length, 0.45 * width), (210, 215, 215), 2)
    sprite.ellipse(0.3 * length, 0, 0.1 * length, 0.16 * width, (40, 50, 70))
    return sprite


def _boat(rng: np.random.Generator) -> _Sprite:
    """A hull with a pointed bow, a cabin, and a V-shaped wake behind the stern."""
    length = rng.uniform(50.0, 100.0)
    width = length * rng.uniform(0.28, 0.4)
    wake = length * rng.uniform(0.4, 0.9)
    sprite = _Sprite(math.hypot(length / 2 + wake, width / 2 + 0.45 * wake), rng.uniform(0.0, 2 * math.pi))
    stern = -length / 2
    sprite.polygon([(stern, -width / 2), (stern - wake, -width / 2 - 0.45 * wake),
                    (stern - wake, width / 2 + 0.45 * wake), (stern, width / 2)], foam=60)
    sprite.polygon([(stern, -0.25 * width), (stern - 0.8 * wake, -0.4 * width),
                    (stern - 0.8 * wake, 0.4 * width), (stern, 0.25 * width)], foam=150)
    hull = [(stern, -width / 2), (0.2 * length, -width / 2), (0.38 * length, -0.3 * width), (length / 2, 0),
            (0.38 * length, 0.3 * width), (0.2 * length, width / 2), (stern, width / 2)]
    colour = _pick(rng, [(235, 235, 235), (40, 40, 190), (90, 40, 20), (150, 150, 150), (40, 200, 230)])
    sprite.polygon(hull, colour)
    sprite.polygon([(-0.25 * length, -0.3 * width), (0.1 * length, -0.3 * width),
                    (0.1 * length, 0.3 * width), (-0.25 * length, 0.3 * width)],
                   tuple(int(c * 0.7) for c in colour) if sum(colour) > 300 else (210, 210, 210))
    return sprite


def _irregular(rng: np.random.Generator, u: float, v: float, radius: float) -> list[tuple[float, float]]:
    """A random star-shaped polygon (5-8 corners) around (u, v)."""
    angles = np.sort(rng.uniform(0.0, 2 * math.pi, int(rng.integers(5, 9))))
    radii = rng.uniform(0.5, 1.0, len(angles)) * radius
    return [(u + r * math.cos(a), v + r * math.sin(a)) for a, r in zip(angles, radii)]


def _debris(rng: np.random.Generator) -> _Sprite:
    """A cluster of irregular dark fragments, sometimes with a plank."""
    spread = rng.uniform(8.0, 20.0)
    sprite = _Sprite(1.6 * spread + 12, rng.uniform(0.0, 2 * math.pi))
    dark = [(30, 45, 60), (40, 40, 40), (25, 60, 90), (70, 70, 70), (20, 35, 50)]
    for _ in range(int(rng.integers(2, 5))):
        sprite.polygon(_irregular(rng, *rng.normal(0.0, 0.5 * spread, 2), rng.uniform(3.0, 9.0)), _pick(rng, dark))
    if rng.random() < 0.5:
        half = rng.uniform(8.0, 14.0)
        sprite.polygon([(-half, -2), (half, -2), (half, 2), (-half, 2)], (45, 80, 110))
    return sprite


def _floating_object(rng: np.random.Generator) -> _Sprite:
    """A small bright buoy, cool box or canister (sometimes two)."""
    sprite = _Sprite(22.0, rng.uniform(0.0, 2 * math.pi))
    bright = [(30, 30, 230), (20, 220, 250), (20, 140, 255), (245, 245, 245), (230, 160, 30)]
    for i in range(1 if rng.random() < 0.7 else 2):
        u, v = (0.0, 0.0) if i == 0 else tuple(rng.uniform(-10.0, 10.0, 2))
        shape, colour = int(rng.integers(3)), _pick(rng, bright)
        if shape == 0:  # buoy with a contrasting ring
            radius = rng.uniform(4.0, 8.0)
            sprite.ellipse(u, v, radius, radius, colour)
            sprite.ellipse(u, v, 0.5 * radius, 0.5 * radius, (240, 240, 240) if sum(colour) < 600 else (30, 30, 200))
        elif shape == 1:  # cool box
            hl, hw = rng.uniform(4.0, 7.0), rng.uniform(3.0, 5.0)
            sprite.polygon([(u - hl, v - hw), (u + hl, v - hw), (u + hl, v + hw), (u - hl, v + hw)], colour)
        else:  # canister or bottle
            sprite.ellipse(u, v, rng.uniform(4.0, 6.0), rng.uniform(1.5, 2.5), colour)
    return sprite


RENDERERS: dict[str, Callable[[np.random.Generator], _Sprite]] = {
    "person": _person, "swimmer": _swimmer, "life_jacket": _life_jacket,
    "boat": _boat, "debris": _debris, "floating_object": _floating_object,
}


# -- one image ----------------------------------------------------------------------------------------------

def synthetic_image(seed: int, index: int) -> tuple[np.ndarray, list[tuple[int, float, float, float, float]]]:
    """Image ``index`` of the dataset made with ``seed``: (640x480 BGR uint8, YOLO boxes (class, cx, cy, w, h))."""
    rng = np.random.default_rng([seed, index])
    image = _sea(rng)
    wanted = [PRIMARY_CHOICES[int(rng.integers(len(PRIMARY_CHOICES)))]]
    others = int(rng.integers(0, MAX_OTHERS + 1))
    wanted += [OTHER_CHOICES[int(rng.integers(len(OTHER_CHOICES)))] for _ in range(others)]
    taken: list[tuple[int, int, int, int]] = []  # drawn extents (x0, y0, x1, y1), kept apart by GAP_PX
    boxes = []
    for category in wanted:  # the primary first: on an empty sea it always finds room
        colour, alpha, (bx, by, bw, bh) = RENDERERS[category](rng).crop()
        height, width = alpha.shape
        for _ in range(50):
            x = int(rng.integers(0, IMAGE_WIDTH - width + 1))
            y = int(rng.integers(0, IMAGE_HEIGHT - height + 1))
            if all(x + width + GAP_PX <= x0 or x1 + GAP_PX <= x or y + height + GAP_PX <= y0 or y1 + GAP_PX <= y
                   for x0, y0, x1, y1 in taken):
                break
        else:
            continue  # no room left for this object: the image has fewer others
        taken.append((x, y, x + width, y + height))
        a = alpha.astype(np.float32)[..., None] / 255.0
        region = image[y:y + height, x:x + width]
        region[...] = region * (1.0 - a) + colour.astype(np.float32) * a
        boxes.append((CATEGORIES.index(category), (x + bx + bw / 2) / IMAGE_WIDTH, (y + by + bh / 2) / IMAGE_HEIGHT,
                      bw / IMAGE_WIDTH, bh / IMAGE_HEIGHT))
    return _light(image, rng), boxes


# -- the dataset --------------------------------------------------------------------------------------------

def split_counts(count: int, fractions: tuple[float, float, float]) -> tuple[int, int, int]:
    """Images per split: the largest-remainder rounding of count x fractions (exactly 140/40/20 for 200)."""
    if len(fractions) != 3 or any(not (f >= 0) for f in fractions) or not math.isclose(sum(fractions), 1.0,
                                                                                          abs_tol=1e-6):
        raise ValueError(f"split must be three fractions >= 0 that sum to 1, got {fractions!r}")
    exact = [count * f for f in fractions]
    counts = [math.floor(e) for e in exact]
    by_remainder = sorted(range(3), key=lambda i: exact[i] - counts[i], reverse=True)
    for i in by_remainder[:count - sum(counts)]:
        counts[i] += 1
    return counts[0], counts[1], counts[2]


def _write_atomic(path: Path, data: bytes) -> None:
    """Write to a hidden temporary name, then rename: a file is either complete or absent."""
    temporary = path.with_name(f".{path.name}.tmp")
    try:
        temporary.write_bytes(data)
        os.replace(temporary, path)
    except BaseException:  # including Ctrl-C: leave no half-written temporary behind
        temporary.unlink(missing_ok=True)
        raise


def _prepare(out: Path, overwrite: bool) -> None:
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"{out} exists and is not a directory")
    if out.is_dir() and any(out.iterdir()):
        if not overwrite:
            raise FileExistsError(f"{out} is not empty; choose an empty directory or overwrite "
                                  "(--overwrite, overwrite=True) to replace the dataset in it")
        # Only what this function writes is removed; data.yaml first, so an interrupted clean-up never
        # leaves a dataset that looks complete.
        (out / "data.yaml").unlink(missing_ok=True)
        for name in ("images", "labels"):
            if (out / name).is_dir():
                shutil.rmtree(out / name)
    for kind in ("images", "labels"):
        for split in SPLITS:
            (out / kind / split).mkdir(parents=True, exist_ok=True)


def make_synthetic_dataset(out_dir: str | Path, count: int = 200, seed: int = 0,
                           split: tuple[float, float, float] = (0.7, 0.2, 0.1), progress: Progress | None = None,
                           overwrite: bool = False) -> DatasetSummary:
    """Write the synthetic SAR dataset (``count`` images, train/val/test by ``split``) as YOLO files.

    Refuses a non-empty ``out_dir`` (FileExistsError) unless ``overwrite``, which replaces its data.yaml,
    images/ and labels/ and leaves anything else alone. Images 0..n_train-1 form the train split, the next
    ones val, the rest test (every image is an independent draw, so the order carries no bias).
    """
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise ValueError(f"count must be an integer >= 1, got {count!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
    sizes = split_counts(count, split)
    out = Path(out_dir)
    started = time.perf_counter()
    _prepare(out, overwrite)
    boxes: Counter[str] = Counter({c: 0 for c in CATEGORIES})
    index = 0
    for split_name, size in zip(SPLITS, sizes):
        for _ in range(size):
            image, labels = synthetic_image(seed, index)
            name = f"synth_{index:05d}"
            ok, png = cv2.imencode(".png", image)
            if not ok:
                raise OSError(f"cannot encode {name}.png")
            # The label goes first: an image without its label would read as an empty sea.
            _write_atomic(out / "labels" / split_name / f"{name}.txt",
                          "".join(f"{c} {cx:.6f} {cy:.6f} {w:.6f} {h:.6f}\n" for c, cx, cy, w, h in labels).encode())
            _write_atomic(out / "images" / split_name / f"{name}.png", png.tobytes())
            boxes.update(CATEGORIES[c] for c, *_ in labels)
            index += 1
            if progress is not None:
                progress(index, count)
    data = {"path": str(out.resolve()), "train": "images/train", "val": "images/val", "test": "images/test",
            "nc": len(CATEGORIES), "names": list(CATEGORIES)}
    header = f"# Synthetic maritime SAR dataset: {count} images, seed {seed} (hrlsac dataset synth)\n"
    _write_atomic(out / "data.yaml",
                  (header + yaml.safe_dump(data, sort_keys=False, default_flow_style=None)).encode())
    images = dict(zip(SPLITS, sizes))
    return DatasetSummary(out, images=images, boxes=dict(boxes), scenarios=dict(images),
                          seconds=time.perf_counter() - started)
