"""What a mission leaves behind in its output folder: the tlog, the JSON report, a trajectory PNG, an MP4 replay.

* ``flight.tlog``: every MAVLink message in both directions, each prefixed by the 8-byte big-endian time in
  microseconds (the tlog format of MAVProxy and QGroundControl; ``mavlogdump.py flight.tlog`` reads it). The
  time is the run's clock: simulated seconds from 0 in lockstep replay (so replays are byte-identical), wall
  seconds since the start in real time. Written unbuffered message by message, so a killed run leaves a
  readable log up to the kill.
* ``report.json``: the runner's report, written atomically (a temporary file, then a rename).
* ``trajectory.png`` and ``replay.mp4``: the search drawn by ``missions.render`` after every decision.
"""
from __future__ import annotations

import json
import os
import struct
import tempfile
from pathlib import Path

import cv2
import numpy as np

TLOG = "flight.tlog"
REPORT = "report.json"
TRAJECTORY = "trajectory.png"
VIDEO = "replay.mp4"
VIDEO_FPS = 20


class TlogRecorder:
    """Appends timestamped MAVLink frames to a tlog file."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self._file = open(self.path, "wb", buffering=0)
        self.messages = 0

    def record(self, time_s: float, data: bytes) -> None:
        self._file.write(struct.pack(">Q", int(round(time_s * 1e6))) + data)
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


class VideoRecorder:
    """Frames (RGB) into an MP4 (OpenCV's mp4v codec); the last frame is also the trajectory PNG."""

    def __init__(self, folder: Path):
        self.folder = Path(folder)
        self._writer = None
        self.last_frame: np.ndarray | None = None
        self.frames = 0

    def add(self, rgb: np.ndarray) -> None:
        bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
        if self._writer is None:
            height, width = bgr.shape[:2]
            self._writer = cv2.VideoWriter(str(self.folder / VIDEO), cv2.VideoWriter_fourcc(*"mp4v"), VIDEO_FPS,
                                           (width, height))
        self._writer.write(bgr)
        self.last_frame = bgr
        self.frames += 1

    def close(self) -> None:
        if self._writer is not None:
            self._writer.release()
        if self.last_frame is not None:
            cv2.imwrite(str(self.folder / TRAJECTORY), self.last_frame)
