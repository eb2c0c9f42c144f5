"""An RGB-only robot's camera, read from a bag through the pose model (cognition.pose, the
`camera` extra) into what `beyond video` records of a video: the person's image, their skeleton
and where its joints are in the image, one stamp for the three (the ROS message's own)."""

from __future__ import annotations

from typing import Any

import numpy as np

from beyond_self.schemas.base import Header, Message

SOURCE = "ros2"


class PersonCamera:
    """Consecutive images of one camera -> (stream, message) pairs, as services.pose_source
    makes them from a video or a camera."""

    def __init__(self) -> None:
        from beyond_self.cognition.pose.estimator import PoseEstimator

        self.estimator: Any = PoseEstimator(video=True)
        self.index = 0
        self.seqs: dict[type[Message], int] = {}

    def messages(self, image: tuple[int, np.ndarray]) -> list[tuple[str, Message]]:
        from beyond_self.runtime.recording.person import PersonFrame, person_messages

        stamp, rgb = image

        def header(cls: type[Message]) -> Header:
            seq = self.seqs[cls] = self.seqs.get(cls, 0) + 1
            return cls.original_header(SOURCE, seq, stamp, chain=cls.type_name())

        frame = PersonFrame(self.index, rgb, self.estimator.estimate(rgb))
        self.index += 1
        return person_messages(header, frame)

    def close(self) -> None:
        self.estimator.close()
