"""What every benchmark script shares: medians over repeated runs and an atomically written JSON report."""
from __future__ import annotations

import json
import os
import statistics
import sys
import time

RESULTS_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")


def results_file(name: str) -> str:
    """The default --out of a benchmark: benchmarks/results/NAME, wherever the script is run from."""
    return os.path.join(RESULTS_DIR, name)


def summarise(runs: dict[str, list[float]], title: str) -> dict[str, float]:
    """Print each figure's median (with min and max) over the runs; return the medians."""
    medians = {name: statistics.median(values) for name, values in runs.items()}
    print(f"\n{title}")
    for name, value in medians.items():
        print(f"  {name:40s} {value:14,.1f}   (min {min(runs[name]):,.1f}, max {max(runs[name]):,.1f})")
    return medians


def write_report(path: str, report: dict) -> None:
    """Write the report (plus the command and the time it was measured) to ``path`` atomically."""
    report = {"command": "python " + " ".join(sys.argv), **report,
              "measured_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    with open(path + ".tmp", "w") as handle:
        json.dump(report, handle, indent=2)
    os.replace(path + ".tmp", path)
    print(f"written {path}")
