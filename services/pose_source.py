"""A camera watching a person, as the ingest's live source: frames from a video file or a camera
through the pose model (cognition.pose) become skeleton items, and the frames themselves the
person's camera stream. It has the shape of an ingest plug-in (an async iterator of
`("skeleton", {joint: (x, y, z, confidence)})` and `("person_camera", rgb)` items), run by the
ingest itself, so the model runs where the camera is: on the robot's side.

A video file is watched as a camera would show it, at its own pace (its frame times against
the wall clock); when the model is slower than the video, a frame more than one interval late
is not estimated (shed, counted), so the pose keeps up with the picture instead of falling
further behind. A frame with nobody in it gives no skeleton (counted).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from beyond_self.cognition.pose.skeleton import PoseEstimate, kinect_joints
from beyond_self.cognition.pose.video import Video
from beyond_self.runtime.images import message_from_image
from beyond_self.schemas import CompressedCameraFrame, Header, Joint

PERSON_CAMERA_FRAME = "person_camera"  # the frame id of the person's images
JPEG_QUALITY = 80  # as the shipped recordings' camera


def joints_of(items: Mapping[str, Sequence[float]]) -> dict[str, Joint]:
    """Skeleton joints from `joint -> (x, y, z)` or `(x, y, z, confidence)` (metres, [0, 1]):
    what a live source yields, and what `beyond video` records, made the same way."""
    joints = {}
    for name, p in items.items():
        x, y, z = (float(v) for v in p[:3])
        confidence = float(p[3]) if len(p) > 3 else 1.0
        joints[name] = Joint(position=(x, y, z), confidence=confidence)
    return joints


def person_image(header: Header, rgb: Any) -> CompressedCameraFrame:
    """The person's camera frame as published and recorded: JPEG, the same way everywhere."""
    image = message_from_image(
        header, rgb, fmt="jpeg", quality=JPEG_QUALITY, frame_id=PERSON_CAMERA_FRAME
    )
    assert isinstance(image, CompressedCameraFrame)  # fmt jpeg
    return image


def pose_joints(pose: PoseEstimate) -> dict[str, tuple[float, float, float, float]]:
    """A pose's skeleton as a live source yields it: joint -> (x, y, z, confidence)."""
    return {name: (*xyz, c) for name, (xyz, c) in kinect_joints(pose).items()}


@dataclass
class PoseCounts:
    frames: int = 0  # read from the video or camera
    skeletons: int = 0  # frames a person was seen in
    no_person: int = 0  # estimated, nobody there
    shed: int = 0  # not estimated: the model was more than a frame behind the video


class PoseSource:
    """`async for kind, payload in PoseSource(video=...)`: a video file or a camera, live."""

    def __init__(self, *, video: str | None = None, camera: int | None = None) -> None:
        self.video_path, self.camera = video, camera
        self.counts = PoseCounts()

    def __aiter__(self) -> AsyncIterator[tuple[str, Any]]:
        return self._items()

    async def _items(self) -> AsyncIterator[tuple[str, Any]]:
        from beyond_self.cognition.pose.estimator import PoseEstimator

        video = await asyncio.to_thread(Video, self.video_path, camera=self.camera)
        try:
            estimator = await asyncio.to_thread(PoseEstimator, video=True)
            try:
                frames = video.frames()
                interval = 1e9 / video.fps
                start: int | None = None
                while True:
                    frame = await asyncio.to_thread(next, frames, None)
                    if frame is None:
                        break
                    self.counts.frames += 1
                    if not video.is_camera:  # a file: shown at its own pace
                        now = time.monotonic_ns()
                        start = now - frame.time_ns if start is None else start
                        due = start + frame.time_ns
                        if now < due:
                            await asyncio.sleep((due - now) / 1e9)
                        elif now - due > interval:
                            self.counts.shed += 1
                            yield ("person_camera", frame.rgb)
                            continue
                    pose = await asyncio.to_thread(estimator.estimate, frame.rgb)
                    yield ("person_camera", frame.rgb)  # the image, then its skeleton
                    if pose is None:
                        self.counts.no_person += 1
                    else:
                        self.counts.skeletons += 1
                        yield ("skeleton", pose_joints(pose))
            finally:
                estimator.close()
        finally:
            video.close()
