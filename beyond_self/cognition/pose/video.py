"""Frames and their times from a video file or a camera, through OpenCV's `VideoCapture`.

A file's frames carry the file's own times (each frame's presentation time, from the
container), so a recording made from it is the same whenever and however fast it is made; a
time that does not move forward (a container without them) is replaced by the previous one plus
one frame interval at the file's rate. A camera's frames are stamped by whoever reads them.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, Self

import numpy as np

from beyond_self.core.errors import InputError

DEFAULT_FPS = 30.0  # a file that does not say its rate
CAMERA_INDEX_MAX = 63


@dataclass(frozen=True, eq=False)
class VideoFrame:
    """Frame `index` (0-based) at `time_ns` after the video's start, RGB uint8 (H, W, 3)."""

    index: int
    time_ns: int
    rgb: np.ndarray


def _cv2() -> Any:
    # FFmpeg inside OpenCV logs a damaged file's complaints ("moov atom not found") straight to
    # stderr; the InputError below says it in one line. 8: FFmpeg's AV_LOG_FATAL.
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "8")
    try:
        import cv2
    except ImportError as exc:
        raise InputError(
            f"OpenCV is not installed ({exc}); install the camera extra: "
            "pip install 'beyond-self[camera]'"
        ) from None
    return cv2


class Closing:
    """Something to close after use, in a `with` block (a capture device, a model's graph)."""

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


class Video(Closing):
    """An opened video file (`path`) or camera (`camera`: its index), read frame by frame."""

    def __init__(self, path: str | Path | None = None, *, camera: int | None = None) -> None:
        if (path is None) == (camera is None):
            raise InputError("a video source needs a file or a camera index, not both")
        cv2 = _cv2()
        self._cv2 = cv2
        if path is not None:
            self.name = str(path)
            p = Path(path)
            if not p.is_file():
                raise InputError(f"video {p} does not exist; valid: a video file (mp4, avi, ...)")
            self._capture = cv2.VideoCapture(str(p))
            if not self._capture.isOpened():
                raise InputError(f"video {p} cannot be read; valid: a video file OpenCV decodes")
        else:
            assert camera is not None
            self.name = f"camera {camera}"
            if not 0 <= camera <= CAMERA_INDEX_MAX:
                raise InputError(
                    f"camera index {camera} out of range; valid: 0..{CAMERA_INDEX_MAX}"
                )
            # each of OpenCV's back ends logs its own failure to open, a dozen lines in all;
            # the InputError below says it in one
            level = cv2.utils.logging.getLogLevel()
            cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
            try:
                self._capture = cv2.VideoCapture(camera)
            finally:
                cv2.utils.logging.setLogLevel(level)
            if not self._capture.isOpened():
                self._capture.release()
                raise InputError(
                    f"camera {camera} does not open (no /dev/video{camera}, or it is busy); "
                    "valid: the index of a connected camera"
                )
        self.is_camera = camera is not None
        fps = float(self._capture.get(cv2.CAP_PROP_FPS))
        self.fps = fps if math.isfinite(fps) and 1.0 <= fps <= 1000.0 else DEFAULT_FPS
        count = int(self._capture.get(cv2.CAP_PROP_FRAME_COUNT))
        self.frame_count: int | None = count if count > 0 and not self.is_camera else None

    def frames(self) -> Iterator[VideoFrame]:
        """Every frame in order, with its time; a file that holds none is an InputError."""
        cv2 = self._cv2
        interval = round(1e9 / self.fps)
        last = -1
        index = 0
        while True:
            ok, bgr = self._capture.read()
            if not ok or bgr is None:
                break
            ms = float(self._capture.get(cv2.CAP_PROP_POS_MSEC))
            t = round(ms * 1e6) if math.isfinite(ms) and ms >= 0 else -1
            if t <= last:
                t = last + interval if last >= 0 else 0
            last = t
            if bgr.ndim == 2:
                rgb = cv2.cvtColor(bgr, cv2.COLOR_GRAY2RGB)
            else:
                rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
            yield VideoFrame(index, t, np.ascontiguousarray(rgb, dtype=np.uint8))
            index += 1
        if index == 0 and not self.is_camera:
            raise InputError(f"video {self.name} holds no frame OpenCV can decode")

    def close(self) -> None:
        self._capture.release()
