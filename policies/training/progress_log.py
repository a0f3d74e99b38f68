"""What a training run tells as it goes: one row of ``progress.csv`` every ``log_every`` steps, the same figures
as tensorboard scalars (``<run>/tensorboard``) and a progress bar on stderr (steps, rate, time left, and the
last row's episodes, success and return; ``policies.reports.progress``).

The columns are ``LOG_FIELDS``; rolling figures are over the last ``WINDOW`` finished episodes. A resumed run
first drops the rows written after its checkpoint (``truncate_after``): they are written again as it continues.
"""
from __future__ import annotations

import csv
import math
import os
from pathlib import Path
from typing import Sequence

import numpy as np

from hrlsac_cli.progress import progress_bar

LOG_FIELDS = ("step", "episodes", "success_rate", "mean_return", "mean_length", "mean_coverage",
              "subgoal_reachability", "critic_loss", "actor_loss", "alpha", "meta_critic_loss", "meta_alpha",
              "meta_entropy", "eval_success_rate", "eval_ran_dry_rate", "steps_per_s")
WINDOW = 100
"""Finished episodes in the rolling statistics."""


def progress_row(step: int, episodes: int, recent: Sequence[tuple], recent_subgoals: Sequence[float],
                 metrics: dict[str, float], steps_per_s: float) -> dict:
    """One log row: ``recent`` holds (success, return, length, coverage) of the last finished episodes,
    ``recent_subgoals`` 1 or 0 per finished goal segment (its point reached in time), ``metrics`` the latest
    losses and temperatures."""
    recent = np.array(recent) if len(recent) else np.zeros((0, 4))

    def mean(column: int) -> float:
        return float(recent[:, column].mean()) if len(recent) else math.nan

    m = metrics
    return {"step": step, "episodes": episodes, "success_rate": mean(0), "mean_return": mean(1),
            "mean_length": mean(2), "mean_coverage": mean(3),
            "subgoal_reachability": float(np.mean(recent_subgoals)) if len(recent_subgoals) else math.nan,
            "critic_loss": m.get("critic_loss", math.nan), "actor_loss": m.get("actor_loss", math.nan),
            "alpha": m.get("alpha", math.nan), "meta_critic_loss": m.get("meta_critic_loss", math.nan),
            "meta_alpha": m.get("meta_alpha", math.nan), "meta_entropy": m.get("meta_entropy", math.nan),
            "eval_success_rate": m.get("eval_success_rate", math.nan),
            "eval_ran_dry_rate": m.get("eval_ran_dry_rate", math.nan), "steps_per_s": steps_per_s}


class ProgressLog:
    """``progress.csv`` (appended to), tensorboard and the progress bar of the run in ``run_dir``, from
    ``first_step`` to ``end_step``; use as a context manager around the training loop."""

    def __init__(self, run_dir: Path, first_step: int, end_step: int, show_progress: bool = True):
        self.run_dir, self.first_step, self.end_step = Path(run_dir), first_step, end_step
        self.show_progress = show_progress
        self._handle = self._writer = self._bar = None
        self._tensorboard = None

    def __enter__(self) -> ProgressLog:
        path = self.run_dir / "progress.csv"
        new_file = not path.exists()
        self._handle = open(path, "a", newline="")
        self._writer = csv.DictWriter(self._handle, fieldnames=LOG_FIELDS)
        if new_file:
            self._writer.writeheader()
        self._bar = progress_bar(self.end_step, "step", "training", self.show_progress, initial=self.first_step)
        return self

    def __exit__(self, *exc) -> None:
        self._bar.close()
        self._handle.close()

    def advance(self, step: int) -> None:
        """The run is at ``step``: the bar moves on."""
        self._bar.advance_to(step)

    def write(self, row: dict) -> None:
        """Log ``row`` (``progress_row``) everywhere; the bar shows its episodes, success and return."""
        self._writer.writerow(row)
        self._handle.flush()
        self._add_scalars(row)
        shown = [f"episodes {row['episodes']}"]
        if row["episodes"]:
            shown += [f"success {row['success_rate']:.0%}", f"return {row['mean_return']:.1f}"]
        if not math.isnan(row["eval_success_rate"]):
            shown.append(f"val success {row['eval_success_rate']:.0%}")
        self._bar.set_postfix_str(", ".join(shown), refresh=False)

    def close(self) -> None:
        """Close tensorboard's writer (the csv file closes with the context)."""
        if self._tensorboard:
            self._tensorboard.close()

    def _add_scalars(self, row: dict) -> None:
        try:
            if self._tensorboard is None:
                from torch.utils.tensorboard import SummaryWriter

                self._tensorboard = SummaryWriter(str(self.run_dir / "tensorboard"), purge_step=self.first_step)
        except ImportError:  # tensorboard comes with the train extra, but training must not die for a log
            self._tensorboard = False
        if self._tensorboard:
            for key, value in row.items():
                if key != "step" and not math.isnan(value):
                    self._tensorboard.add_scalar(key, value, row["step"])


def truncate_after(run_dir: Path, step: int) -> None:
    """Drop the rows of ``run_dir``'s progress.csv written after ``step`` (atomically: a crash keeps the old file)."""
    path = Path(run_dir) / "progress.csv"
    if not path.exists():
        return
    with open(path, newline="") as handle:
        rows = [row for row in csv.DictReader(handle) if int(row["step"]) <= step]
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=LOG_FIELDS)
        writer.writeheader()
        writer.writerows(rows)
    os.replace(tmp, path)
