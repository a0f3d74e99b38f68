"""``hrlsac dataset``: make the synthetic SAR dataset or inspect a YOLO dataset.

    hrlsac dataset synth OUT [--count 200] [--seed 0] [--overwrite]
    hrlsac dataset info ROOT [--strict] [--names a,b,c] [--obstacle-classes boat,ship]
"""
from __future__ import annotations

import argparse
import sys
import time

from hrlsac_cli.help_format import HelpFormatter
from missions.datasets import YoloDataset
from missions.scenario import CATEGORIES
from missions.yolo_labels import DatasetError, DatasetSummary


def build_parser(prog: str) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description="Make the synthetic SAR dataset or inspect a YOLO dataset.")
    commands = parser.add_subparsers(dest="command", required=True, metavar="{synth,info}")
    synth = commands.add_parser("synth", help="write the synthetic maritime dataset (YOLO format, 640x480 PNG)",
                                formatter_class=HelpFormatter)
    synth.add_argument("out", metavar="OUT", help="output directory (created; must be empty unless --overwrite)")
    synth.add_argument("--count", type=int, default=200, help="number of images (split 70/20/10)")
    synth.add_argument("--seed", type=int, default=0, help="seed: the same seed writes identical files")
    synth.add_argument("--overwrite", action="store_true",
                       help="replace data.yaml, images/ and labels/ of a non-empty OUT")
    info = commands.add_parser("info", help="splits, images, boxes per category and what was skipped")
    info.add_argument("root", metavar="ROOT", help="dataset directory (with data.yaml, or images/{train,val,test})")
    info.add_argument("--names", help="comma-separated class names by id (overrides data.yaml)")
    info.add_argument("--obstacle-classes", default="", help="comma-separated class names that are obstacles")
    info.add_argument("--strict", action="store_true", help="fail on the first malformed label line")
    return parser


def _split_list(text: str | None) -> list[str] | None:
    return None if text is None else [part.strip() for part in text.split(",") if part.strip()]


def _category_counts(boxes: dict[str, int]) -> str:
    return ", ".join(f"{c} {boxes.get(c, 0)}" for c in CATEGORIES)


def _synth(args: argparse.Namespace) -> int:
    from missions.synthetic import make_synthetic_dataset  # imports OpenCV; only this command needs it

    step = max(1, args.count // 10)

    def progress(done: int, total: int) -> None:
        if done % step == 0 or done == total:
            print(f"  {done}/{total} images", flush=True)

    print(f"Writing {args.count} synthetic images (seed {args.seed}) to {args.out}", flush=True)
    summary = make_synthetic_dataset(args.out, count=args.count, seed=args.seed, progress=progress,
                                     overwrite=args.overwrite)
    print(f"Done in {summary.seconds:.1f} s.")
    print("images: " + ", ".join(f"{split} {n}" for split, n in summary.images.items()))
    print(f"boxes: {_category_counts(summary.boxes)}")
    print(f"data.yaml: {summary.data_yaml}")
    return 0


def _info(args: argparse.Namespace) -> int:
    started = time.perf_counter()
    dataset = YoloDataset(args.root, _split_list(args.names), strict=args.strict,
                          obstacle_classes=_split_list(args.obstacle_classes) or ())
    summary: DatasetSummary = dataset.summary()
    source = dataset.yaml_path if dataset.yaml_path else "folder layout, no data.yaml"
    print(f"Dataset {dataset.root} ({source})")
    classes = []
    for class_id, name in sorted(dataset.names.items()):
        category = dataset.categories[class_id]
        role = "obstacle" if class_id in dataset.obstacle_ids else (category or "unmapped, skipped")
        classes.append(f"{class_id} {name} -> {role}")
    print("classes: " + "; ".join(classes))
    print(f"{'split':<6} {'images':>7} {'scenarios':>10}")
    for split in dataset.splits():
        print(f"{split:<6} {summary.images[split]:>7} {summary.scenarios[split]:>10}")
    total_images, total_scenarios = sum(summary.images.values()), sum(summary.scenarios.values())
    print(f"{'total':<6} {total_images:>7} {total_scenarios:>10}")
    print(f"boxes: {_category_counts(summary.boxes)}; obstacles {summary.obstacles}")
    unknown = ", ".join(f"{name} {n}" for name, n in sorted(summary.unknown_classes.items()))
    print(f"skipped: {summary.skipped_lines} malformed label line(s); "
          f"{sum(summary.unknown_classes.values())} box(es) of unmapped classes{f' ({unknown})' if unknown else ''}; "
          f"{total_images - total_scenarios} image(s) without a person/swimmer/life_jacket (no scenario); "
          f"{summary.orphan_labels} label file(s) without an image; {summary.missing_images} listed image(s) missing")
    for problem in summary.problems:
        print(f"  {problem}")
    print(f"Read in {time.perf_counter() - started:.1f} s.")
    return 0


def main(argv: list[str], prog: str = "hrlsac dataset") -> int:
    """Entry point of ``hrlsac dataset``: bad input is a one-line error and exit code 2."""
    args = build_parser(prog).parse_args(argv)
    try:
        return _synth(args) if args.command == "synth" else _info(args)
    except (DatasetError, ValueError, OSError) as exc:
        print(f"{prog} {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        if args.command == "synth":
            print(f"{prog} synth: interrupted; the images written so far are complete, "
                  f"but {args.out} has no data.yaml", file=sys.stderr)
        else:
            print(f"{prog} {args.command}: interrupted", file=sys.stderr)
        return 130
