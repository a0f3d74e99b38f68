"""The live progress table of a sweep: one row per run (state, steps done / total, training success).

On a terminal the table is redrawn in place (cursor up, clear to the end of the screen); into a file or a pipe
it prints one plain line each time a run changes state, so logs stay readable, and the whole table at the end.
"""
from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

PENDING, RUNNING, DONE, SKIPPED, FAILED = "pending", "running", "done", "skipped", "failed"


@dataclass
class RunStatus:
    """What the table shows of one run."""

    name: str
    """Run name (= run folder name)."""
    folder: Path
    """The run folder."""
    total_steps: int
    """Steps the run trains for."""
    state: str = PENDING
    """pending, running, done (trained in this sweep), skipped (finished before it) or failed."""
    steps: int = 0
    """Environment steps done (from the run's progress.csv while it runs)."""
    success_rate: float = math.nan
    """Training success over the last 100 episodes (the progress.csv column)."""
    message: str = ""
    """Why a run failed, or where a run resumed from."""

    def as_dict(self) -> dict:
        return {"name": self.name, "folder": str(self.folder), "state": self.state, "steps": self.steps,
                "total_steps": self.total_steps,
                "success_rate": None if math.isnan(self.success_rate) else self.success_rate, "message": self.message}


def render(rows: list[RunStatus]) -> list[str]:
    """The table's lines (header, one line per run, a summary line)."""
    width = max([len(row.name) for row in rows] + [3])
    steps = [f"{row.steps:,}/{row.total_steps:,}" for row in rows]
    steps_width = max([len(text) for text in steps] + [5])
    lines = [f"{'run':<{width}}  {'state':<8}  {'steps':>{steps_width}}  {'success':>7}  note"]
    for row, done in zip(rows, steps):
        success = "-" if math.isnan(row.success_rate) else f"{row.success_rate:.0%}"
        lines.append(f"{row.name:<{width}}  {row.state:<8}  {done:>{steps_width}}  {success:>7}  {row.message}".rstrip())
    counts = {state: sum(row.state == state for row in rows) for state in (DONE, SKIPPED, RUNNING, PENDING, FAILED)}
    lines.append(", ".join(f"{count} {state}" for state, count in counts.items() if count) + f" of {len(rows)} runs")
    return lines


class ProgressTable:
    """Shows :class:`RunStatus` rows on ``stream`` (in place on a terminal, as state-change lines otherwise)."""

    def __init__(self, stream: TextIO | None = None, live: bool | None = None):
        self.stream = stream or sys.stdout
        self.live = self.stream.isatty() if live is None else live
        self._drawn = 0  # lines of the last in-place drawing
        self._states: dict[str, str] = {}

    def update(self, rows: list[RunStatus]) -> None:
        """Show the current state of every run."""
        if self.live:
            self._redraw(render(rows))
            return
        for row in rows:
            if self._states.get(row.name) != row.state:
                self._states[row.name] = row.state
                if row.state != PENDING:
                    note = f" ({row.message})" if row.message else ""
                    self._print(f"{time.strftime('%H:%M:%S')} {row.name}: {row.state} at {row.steps:,}/"
                                f"{row.total_steps:,} steps{note}")

    def finish(self, rows: list[RunStatus]) -> None:
        """The final table (on a terminal it replaces the live one)."""
        if self.live:
            self._redraw(render(rows))
            self._drawn = 0
        else:
            self.update(rows)
            self._print("\n".join(render(rows)))

    def _redraw(self, lines: list[str]) -> None:
        up = f"\x1b[{self._drawn}F\x1b[J" if self._drawn else ""
        self.stream.write(up + "\n".join(lines) + "\n")
        self.stream.flush()
        self._drawn = len(lines)

    def _print(self, line: str) -> None:
        print(line, file=self.stream, flush=True)
