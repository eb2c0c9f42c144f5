"""The pose model: MediaPipe 0.10.14's BlazePose (`solutions.pose`), the full landmark network,
run from the files its wheel bundles (docs/decisions.md: why this version).

For a video the model tracks (`static_image_mode=False`): the person detector runs only when the
landmarks of the previous frame are lost, and the landmarks are smoothed over frames, so the
same frames in the same order always give the same poses; for a still it detects afresh.
"""

from __future__ import annotations

import contextlib
import os
import warnings
from collections.abc import Iterator
from typing import Any

import numpy as np

from beyond_self.cognition.pose.skeleton import LANDMARKS, PoseEstimate
from beyond_self.cognition.pose.video import Closing
from beyond_self.core.errors import InputError

MODEL_COMPLEXITY = 1  # 0 lite, 1 full, 2 heavy: the wheel bundles the full one only
EXTRA_HINT = "install the camera extra: pip install 'beyond-self[camera]'"


def _solutions_pose() -> Any:
    try:
        from mediapipe.python.solutions import pose
    except ImportError as exc:
        raise InputError(f"the pose model is not installed ({exc}); {EXTRA_HINT}") from None
    return pose


@contextlib.contextmanager
def _native_stderr_muted() -> Iterator[None]:
    """The model's native start-up chatter (TensorFlow Lite's delegate, absl's warnings) goes
    straight to file descriptor 2, past Python; a command's one-line answer must stay one line."""
    try:
        saved = os.dup(2)
    except OSError:  # no stderr at all: nothing to mute
        yield
        return
    try:
        with open(os.devnull, "wb") as devnull:
            os.dup2(devnull.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


class PoseEstimator(Closing):
    """One person's pose per RGB image. `video=True`: consecutive frames of one stream."""

    def __init__(self, *, video: bool = True) -> None:
        pose = _solutions_pose()
        self.video = video
        with _native_stderr_muted():
            self._model = pose.Pose(
                static_image_mode=not video,
                model_complexity=MODEL_COMPLEXITY,
                smooth_landmarks=True,
                enable_segmentation=False,
            )
            # the graph loads its networks on the first image: do it now, quietly
            self._model.process(np.zeros((64, 64, 3), dtype=np.uint8))

    def estimate(self, rgb: np.ndarray) -> PoseEstimate | None:
        """The pose of the person in `rgb` ((H, W, 3) uint8), or None when there is none."""
        image = np.ascontiguousarray(rgb, dtype=np.uint8)
        if image.ndim != 3 or image.shape[2] != 3:
            raise InputError(f"image has shape {image.shape}; valid: (height, width, 3) RGB")
        with warnings.catch_warnings():
            # protobuf 4.25 deprecates a call MediaPipe 0.10.14 makes for every result
            warnings.filterwarnings("ignore", message="SymbolDatabase.GetPrototype")
            result = self._model.process(image)
        if result.pose_landmarks is None or result.pose_world_landmarks is None:
            return None
        h, w = image.shape[:2]
        image_marks = result.pose_landmarks.landmark
        world_marks = result.pose_world_landmarks.landmark
        if len(image_marks) != len(LANDMARKS) or len(world_marks) != len(LANDMARKS):
            return None
        pixels = np.array([(m.x * w, m.y * h) for m in image_marks], dtype=np.float64)
        world = np.array([(m.x, m.y, m.z) for m in world_marks], dtype=np.float64)
        visibility = np.array([m.visibility for m in image_marks], dtype=np.float64)
        if not (np.isfinite(world).all() and np.isfinite(pixels).all()):
            return None
        return PoseEstimate(world, pixels, np.clip(visibility, 0.0, 1.0), w, h)

    def close(self) -> None:
        self._model.close()
