"""Progress bars of the long commands (tqdm: train, sweep, evaluate, compare, multi-episode replay), with the rate
and the time left, on stderr. Beside the dispatcher because every package's commands use it (tqdm belongs to the
train extra: the on-board commands never import this module).

On a terminal a bar redraws in place; into a file or a pipe (a log, CI) it writes a plain line at most every
``LOG_EVERY_S`` seconds, the first after that long (a shorter task leaves no line), so that a long run does not
flood its log. A bar only writes to its stream: no output file and no random generator depends on it, and a
disabled one (``--quiet``) writes nothing.
"""
from __future__ import annotations

import sys
from typing import Callable, TextIO

from tqdm import tqdm

REDRAW_EVERY_S = 0.2
"""How often a bar redraws on a terminal."""
LOG_EVERY_S = 30.0
"""How often a bar writes a line when its stream is not a terminal."""


class _Lines:
    """A stream that is not a terminal, as tqdm's file: each redraw on a line of its own, not after a carriage
    return (which would pile every redraw of a run onto one line of the log)."""

    def __init__(self, stream: TextIO):
        self.stream = stream

    def write(self, text: str) -> None:
        line = text.replace("\r", "").rstrip()
        if line:
            self.stream.write(line + "\n")

    def flush(self) -> None:
        self.stream.flush()


class ProgressBar(tqdm):
    """A tqdm bar on a terminal (redrawn in place) or on another stream (whole lines, at most every LOG_EVERY_S)."""

    def __init__(self, total: int, unit: str, desc: str, enabled: bool, initial: int, stream: TextIO):
        self.stream, self.terminal = stream, stream.isatty()
        super().__init__(total=total, initial=initial, unit=unit, desc=desc or None, disable=not enabled,
                         file=stream if self.terminal else _Lines(stream), dynamic_ncols=self.terminal,
                         mininterval=REDRAW_EVERY_S if self.terminal else LOG_EVERY_S,
                         delay=0 if self.terminal else LOG_EVERY_S)

    def note(self, text: str) -> None:
        """A line of its own (one result as the work goes on): above the bar on a terminal, else just the line
        (tqdm's own write would draw the bar with it, before its first interval is up)."""
        if self.disable:
            return
        if self.terminal:
            self.write(text, file=self.fp)
        else:
            print(text, file=self.stream, flush=True)

    def follow(self) -> Callable[[int], None]:
        """A callback for a piece of work that counts what it has done from 0: it moves the bar on from here."""
        start = self.n
        return lambda done: self.advance_to(start + done)

    def advance_to(self, count: int) -> None:
        """Move on to ``count`` (a count of what is done so far, from a callback)."""
        if count > self.n:
            self.update(count - self.n)


def progress_bar(total: int, unit: str, desc: str = "", enabled: bool = True, initial: int = 0,
                 stream: TextIO | None = None) -> ProgressBar:
    """A bar counting ``unit`` up to ``total`` (from ``initial``: a resumed run's rate counts only what it did) on
    ``stream`` (default stderr); ``enabled=False`` gives a bar that shows nothing."""
    return ProgressBar(total, unit, desc, enabled, initial, stream or sys.stderr)
