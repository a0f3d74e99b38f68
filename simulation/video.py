"""The pictures of a replay: ``replay.mp4`` (the search drawn by ``missions.render`` after every decision) and
``trajectory.png`` (its last frame). Kept out of the on-board recorder so that a companion computer needs no
OpenCV."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

TRAJECTORY = "trajectory.png"
VIDEO = "replay.mp4"
VIDEO_FPS = 20


class VideoRecorder:
    """Frames (RGB) into an MP4 (OpenCV's mp4v codec); the last frame is also the trajectory PNG. With ``video``
    False only the PNG is written."""

    def __init__(self, folder: Path, video: bool = True):
        self.folder = Path(folder)
        self.video = video
        self._writer = None
        self.last_frame: np.ndarray | None = None
        self.frames = 0

    def add(self, rgb: np.ndarray) -> None:
        bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
        if self.video:
            if self._writer is None:
                height, width = bgr.shape[:2]
                self._writer = cv2.VideoWriter(str(self.folder / VIDEO), cv2.VideoWriter_fourcc(*"mp4v"),
                                               VIDEO_FPS, (width, height))
            self._writer.write(bgr)
        self.last_frame = bgr
        self.frames += 1

    def close(self) -> None:
        if self._writer is not None:
            self._writer.release()
        if self.last_frame is not None:
            cv2.imwrite(str(self.folder / TRAJECTORY), self.last_frame)
