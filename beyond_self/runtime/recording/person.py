"""What a camera watching a person records per frame, wherever the frames come from (a video,
a camera, a ROS 2 image topic): the person's image (JPEG), their skeleton and where its joints are
in the image, one stamp for the three. The ingest's pose source, `beyond video` and a bag's
RGB-only camera all make their messages here, so they record the same."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from beyond_self.cognition.pose.skeleton import PoseEstimate, kinect_joints, pixel_joints
from beyond_self.runtime.recording.images import message_from_image
from beyond_self.schemas import (
    CompressedCameraFrame,
    Header,
    Joint,
    Keypoint,
    Message,
    PersonPose,
    SkeletonFrame,
)

PERSON_CAMERA_FRAME = "person_camera"  # the frame id of the person's images
SKELETON_FRAME = "person"  # the skeleton's frame: the torso at the origin, OpenNI's axes
JPEG_QUALITY = 80  # as the shipped recordings' camera


@dataclass(frozen=True, eq=False)
class PersonFrame:
    """One frame of a pose source: frame `index` (0-based), its image, its pose if one was
    estimated (None: nobody there, or shed)."""

    index: int
    rgb: np.ndarray
    pose: PoseEstimate | None


def person_messages(
    header: Callable[[type[Message]], Header], frame: PersonFrame
) -> list[tuple[str, Message]]:
    """One frame's messages, each with its stream name (schemas.keys.STREAMS): the image, then
    the skeleton and the pose in the image if a person was seen. `header(cls)` gives each its
    header (one stamp for all three)."""
    image = message_from_image(
        header(CompressedCameraFrame),
        frame.rgb,
        fmt="jpeg",
        quality=JPEG_QUALITY,
        frame_id=PERSON_CAMERA_FRAME,
    )
    out: list[tuple[str, Message]] = [("person_camera", image)]
    pose = frame.pose
    if pose is None:
        return out
    joints = {
        name: Joint(position=xyz, confidence=c) for name, (xyz, c) in kinect_joints(pose).items()
    }
    skeleton = SkeletonFrame(
        header=header(SkeletonFrame),
        frame=frame.index + 1,
        joints=joints,
        frame_id=SKELETON_FRAME,
    )
    keypoints = {
        name: Keypoint(position=uv, confidence=joints[name].confidence)
        for name, uv in pixel_joints(pose).items()
    }
    in_image = PersonPose(
        header=header(PersonPose),
        frame=frame.index + 1,
        width=pose.width,
        height=pose.height,
        keypoints=keypoints,
        frame_id=PERSON_CAMERA_FRAME,
    )
    return [*out, ("skeleton", skeleton), ("person_pose", in_image)]
