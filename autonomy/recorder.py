"""What a mission leaves behind in its output folder: the tlog and the JSON report (a replay adds pictures).

* ``flight.tlog``: every MAVLink message in both directions, each prefixed by the 8-byte big-endian time in
  microseconds since the Unix epoch (the tlog format of MAVProxy and QGroundControl; ``mavlogdump.py flight.tlog``
  reads it). The time is the run's clock plus the start time the recorder is given: simulated seconds after a
  configurable, fixed start in lockstep replay (so replays are byte-identical and tools such as ``mavtogpx.py``
  date their points), wall seconds since the start in real time. Written unbuffered message by message, so a
  killed run leaves a readable log up to the kill.
* ``report.json``: the runner's report, written atomically (a temporary file, then a rename). While the run is
  going, a partial report marked ``"complete": false`` is rewritten the same way (when the run starts, then at most
  once per wall second as it goes, see :class:`PartialReport`); the last write has ``"complete": true``. A killed
  run therefore leaves the report of its state at most a second before the kill, never a torn file.
* ``trajectory.png`` and ``replay.mp4`` (replays only, ``simulation.video``): the search drawn after every decision.
"""
from __future__ import annotations

import json
import math
import os
import struct
import tempfile
import time
from pathlib import Path
from typing import Callable

TLOG = "flight.tlog"
REPORT = "report.json"


class TlogRecorder:
    """Appends timestamped MAVLink frames to a tlog file; ``start_us``: the time stamped for the run's time 0
    (microseconds since the Unix epoch)."""

    def __init__(self, path: Path, start_us: int = 0):
        self.path = Path(path)
        self.start_us = start_us
        self._file = open(self.path, "wb", buffering=0)
        self.messages = 0

    def record(self, time_s: float, data: bytes) -> None:
        self._file.write(struct.pack(">Q", self.start_us + int(round(time_s * 1e6))) + data)
        self.messages += 1

    def close(self) -> None:
        self._file.close()


def write_json_atomic(path: Path, data: dict) -> None:
    """Write JSON so that the file is either the old one or the complete new one, never half of it."""
    path = Path(path)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(handle, "w") as file:
            json.dump(data, file, indent=2, sort_keys=False)
            file.write("\n")
        os.chmod(temporary, 0o644)  # mkstemp makes it owner-only; a report is for everyone to read
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


class PartialReport:
    """The report of a run in progress, rewritten atomically with ``"complete": false`` (see the module docstring).

    ``build()`` returns the report as it stands; :meth:`start` writes the first one, :meth:`update` (hooked with
    :meth:`after` where the run reports progress) writes it again once ``min_interval_s`` of wall time has passed
    since the last write (wall time: writing costs wall time, and when it happens never changes what is written,
    so replays stay deterministic), :meth:`finish` writes the final report with ``"complete": true``. With
    ``path`` None nothing is written (a replay without an output folder).
    """

    def __init__(self, path: Path | None, build: Callable[[], dict], min_interval_s: float = 1.0):
        self.path = None if path is None else Path(path)
        self.build = build
        self.min_interval_s = min_interval_s
        self.writes = 0
        self._started = False
        self._last_write = -math.inf

    def start(self) -> None:
        """Write the first partial report; updates before this are ignored (the run is still being set up)."""
        self._started = True
        self.update(force=True)

    def after(self, callback: Callable[..., None]) -> Callable[..., None]:
        """``callback`` followed by :meth:`update`."""
        def call(*args) -> None:
            callback(*args)
            self.update()
        return call

    def update(self, force: bool = False) -> None:
        due = force or time.monotonic() - self._last_write >= self.min_interval_s
        if self.path is not None and self._started and due:
            self._write({**self.build(), "complete": False})

    def finish(self, report: dict) -> None:
        report["complete"] = True
        self._write(report)

    def _write(self, report: dict) -> None:
        if self.path is None:  # no output folder: the caller keeps the returned report
            return
        write_json_atomic(self.path, report)
        self.writes += 1
        self._last_write = time.monotonic()
