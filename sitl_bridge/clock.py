"""Clocks that drive the simulated vehicle: one code path, two notions of time.

The vehicle itself only knows simulated time: it advances by one physics tick per ``step()``. Who decides
when the next tick happens:

* lockstep: the caller, by calling ``step()`` (mission replays, the tests); runs as fast as the CPU allows and
  is bit-reproducible (no wall time leaks into any message);
* :class:`PacedClock`: ticks are paced to real time, optionally sped up (``speed`` = simulated seconds per
  wall second), for real clients over UDP.
"""
from __future__ import annotations

import math
import time


class PacedClock:
    """Paces simulated time to the wall clock, ``speed`` simulated seconds per wall second."""

    def __init__(self, speed: float = 1.0):
        if not 0 < speed < math.inf:  # inf would pace nothing and spin a core
            raise ValueError(f"speed must be > 0 and finite (simulated seconds per wall second), got {speed}")
        self.speed = speed
        self._wall_start = time.monotonic()

    def start(self) -> None:
        """Anchor simulated time 0 to now."""
        self._wall_start = time.monotonic()

    def pace(self, sim_time_s: float) -> None:
        """Sleep until the wall clock reaches ``sim_time_s``; if we are behind, return at once."""
        delay = self._wall_start + sim_time_s / self.speed - time.monotonic()
        if delay > 0:
            time.sleep(delay)
