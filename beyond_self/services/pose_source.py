"""A camera watching a person, as the ingest's live source.

Frames from a video file or a camera go through the pose model (cognition.pose) and become, with
one stamp per frame, the person's image (JPEG), their skeleton and where its joints are in the
image. It is an ingest plug-in, run by the ingest itself, so the model runs where the camera is;
`beyond video` makes the same messages (runtime.recording.person), stamped with the video's times. A
file is shown at its own pace; a frame more than one interval late is not estimated (shed,
counted; its image still published), so the pose keeps up with the picture. A frame with nobody
in it gives no skeleton (counted).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Any

from beyond_self.cognition.pose.video import Video
from beyond_self.runtime.recording.person import PersonFrame


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
                            yield ("person", PersonFrame(frame.index, frame.rgb, None))
                            continue
                    pose = await asyncio.to_thread(estimator.estimate, frame.rgb)
                    if pose is None:
                        self.counts.no_person += 1
                    else:
                        self.counts.skeletons += 1
                    yield ("person", PersonFrame(frame.index, frame.rgb, pose))
            finally:
                estimator.close()
        finally:
            video.close()
