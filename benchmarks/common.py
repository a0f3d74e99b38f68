"""What every benchmark script shares: medians over repeated runs and an atomically written JSON report.

Importing it puts this checkout's root first on ``sys.path``, so that a benchmark measures the code beside it: a
virtual environment's editable install points at the checkout it was made from, and a benchmark run from another
checkout (a git worktree) would otherwise import that one's packages. Import it before the project's packages.
"""
from __future__ import annotations

import importlib.metadata
import json
import os
import platform
import statistics
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)
RESULTS_DIR = os.path.join(ROOT, "benchmarks", "results")


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
    """Write the report (plus the command, the code, the machine and the time it was measured) to ``path``
    atomically. A script's own ``machine`` entry is kept as the machine's ``note``."""
    report = dict(report)
    machine = machine_info()
    if "machine" in report:
        machine["note"] = report.pop("machine")
    report = {"command": "python " + " ".join(sys.argv), **report, "code": code_version(), "machine": machine,
              "measured_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    with open(path + ".tmp", "w") as handle:
        json.dump(report, handle, indent=2)
    os.replace(path + ".tmp", path)
    print(f"written {path}")


def code_version() -> str:
    """The commit of the measured checkout, with "+changes" when its tracked files differ from it ("unknown"
    outside a git checkout)."""
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                                timeout=10, check=True).stdout.strip()
        changed = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT,
                                 capture_output=True, text=True, timeout=10, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return commit + ("+changes" if changed else "")


def machine_info() -> dict[str, object]:
    """What the figures were measured on: the CPU model, its logical cores, the Python and torch versions."""
    try:
        torch_version = importlib.metadata.version("torch")
    except importlib.metadata.PackageNotFoundError:
        torch_version = None
    return {"cpu": cpu_model(), "cores": os.cpu_count(), "python": platform.python_version(),
            "torch": torch_version}


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo (Linux), else what ``platform`` knows."""
    try:
        with open("/proc/cpuinfo") as handle:
            for line in handle:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"
