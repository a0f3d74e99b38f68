"""The runner's two clocks, one code path: simulated lockstep time (simulation.mission_replay.VehicleClock) or real
time."""
from __future__ import annotations

import time
from typing import Protocol


class Clock(Protocol):
    """``now()`` in seconds since the run started; ``advance()`` moves on by one control tick."""

    def now(self) -> float: ...

    def advance(self) -> None: ...


class WallClock:
    """Real time for flights against a real (or real-time simulated) vehicle: ``advance`` sleeps one tick."""

    def __init__(self, tick_s: float = 0.01):
        self.tick_s = tick_s
        self._start = time.monotonic()
        self._next = self._start
        self.started_unix_us = time.time_ns() // 1000
        """The moment ``now()`` counts from, in microseconds since the Unix epoch (what a flight's tlog stamps)."""

    def now(self) -> float:
        return time.monotonic() - self._start

    def advance(self) -> None:
        self._next += self.tick_s
        delay = self._next - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        else:
            self._next = time.monotonic()
