"""The live progress table of a sweep: one row per run (state, steps done / total, training success), and below it
the sweep's progress over all its steps with the rate and the time left (tqdm's meter).

On a terminal the table is redrawn in place (cursor up, clear to the end of the screen); into a file or a pipe
it prints one plain line each time a run changes state, and the progress line at most every
``hrlsac_cli.progress.LOG_EVERY_S``, so logs stay readable, and the whole table at the end.
"""
from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

from tqdm import tqdm

from hrlsac_cli.progress import LOG_EVERY_S

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
        line = f"{row.name:<{width}}  {row.state:<8}  {done:>{steps_width}}  {success:>7}  {row.message}"
        lines.append(line.rstrip())
    counts = {state: sum(row.state == state for row in rows) for state in (DONE, SKIPPED, RUNNING, PENDING, FAILED)}
    lines.append(", ".join(f"{count} {state}" for state, count in counts.items() if count) + f" of {len(rows)} runs")
    return lines


class ProgressTable:
    """Shows :class:`RunStatus` rows on ``stream`` (default stderr; in place on a terminal, as state-change lines
    otherwise) with the sweep's progress line; ``enabled=False`` shows nothing."""

    def __init__(self, stream: TextIO | None = None, live: bool | None = None, enabled: bool = True):
        self.stream = stream or sys.stderr
        self.live = self.stream.isatty() if live is None else live
        self.enabled = enabled
        self._drawn = 0  # lines of the last in-place drawing
        self._states: dict[str, str] = {}
        self._started: tuple[float, int] | None = None  # (time, steps done) at the first update
        self._logged_at = 0.0  # when the last progress line was printed (not live)

    def update(self, rows: list[RunStatus]) -> None:
        """Show the current state of every run."""
        if not self.enabled:
            return
        meter = self.meter(rows)
        if self.live:
            self._redraw(render(rows) + [meter])
            return
        for row in rows:
            if self._states.get(row.name) != row.state:
                self._states[row.name] = row.state
                if row.state != PENDING:
                    note = f" ({row.message})" if row.message else ""
                    self._print(f"{time.strftime('%H:%M:%S')} {row.name}: {row.state} at {row.steps:,}/"
                                f"{row.total_steps:,} steps{note}")
        if time.monotonic() - self._logged_at >= LOG_EVERY_S:
            self._logged_at = time.monotonic()
            self._print(meter)

    def finish(self, rows: list[RunStatus]) -> None:
        """The final table (on a terminal it replaces the live one)."""
        if not self.enabled:
            return
        self.update(rows)
        if self.live:
            self._drawn = 0
        else:
            self._print("\n".join(render(rows) + [self.meter(rows)]))

    def meter(self, rows: list[RunStatus]) -> str:
        """The sweep's steps done of all its steps, with the rate and the time left from the steps trained since the
        first update (runs finished before the sweep count as done, not towards the rate)."""
        now, done = time.monotonic(), sum(row.steps for row in rows)
        if self._started is None:
            self._started, self._logged_at = (now, done), now
        started, initial = self._started
        return tqdm.format_meter(done, sum(row.total_steps for row in rows), now - started, unit="step",
                                 initial=initial, prefix="sweep", ascii=not self.live)

    def _redraw(self, lines: list[str]) -> None:
        up = f"\x1b[{self._drawn}F\x1b[J" if self._drawn else ""
        self.stream.write(up + "\n".join(lines) + "\n")
        self.stream.flush()
        self._drawn = len(lines)

    def _print(self, line: str) -> None:
        print(line, file=self.stream, flush=True)
