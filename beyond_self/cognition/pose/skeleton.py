"""MediaPipe's 33 pose landmarks -> the joints of the article's Kinect/OpenNI skeletons.

The gesture models read `head`, `neck`, `torso`, `{left,right}_{shoulder,elbow,hand}` in metres,
x to the person's right (OpenNI mirrors the image), y up, z away, the hand taken relative to the
torso. MediaPipe's world landmarks have x to the image's right and y down, and a person facing
the camera has their right side on the image's left: so ours = (-x, -y, z) of MediaPipe's, minus
the torso. A joint BlazePose lacks is the mean of the landmarks that bound it (neck: shoulders;
torso: shoulders and hips; head: ears; hand: wrist and two knuckles), with their least
confidence; a confidence is MediaPipe's `visibility`, so a wrist outside the frame is there,
guessed, with a confidence near 0, as an OpenNI "inferred" joint.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

# BlazePose's landmark order (MediaPipe's PoseLandmark enum); names are the person's own sides.
LANDMARKS: tuple[str, ...] = (
    "nose",
    "left_eye_inner",
    "left_eye",
    "left_eye_outer",
    "right_eye_inner",
    "right_eye",
    "right_eye_outer",
    "left_ear",
    "right_ear",
    "mouth_left",
    "mouth_right",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
    "left_pinky",
    "right_pinky",
    "left_index",
    "right_index",
    "left_thumb",
    "right_thumb",
    "left_hip",
    "right_hip",
    "left_knee",
    "right_knee",
    "left_ankle",
    "right_ankle",
    "left_heel",
    "right_heel",
    "left_foot_index",
    "right_foot_index",
)
_INDEX = {name: i for i, name in enumerate(LANDMARKS)}

# our joint -> the landmarks it is the mean of
JOINT_LANDMARKS: dict[str, tuple[str, ...]] = {
    "head": ("left_ear", "right_ear"),
    "neck": ("left_shoulder", "right_shoulder"),
    "torso": ("left_shoulder", "right_shoulder", "left_hip", "right_hip"),
    "left_shoulder": ("left_shoulder",),
    "right_shoulder": ("right_shoulder",),
    "left_elbow": ("left_elbow",),
    "right_elbow": ("right_elbow",),
    "left_hand": ("left_wrist", "left_index", "left_pinky"),
    "right_hand": ("right_wrist", "right_index", "right_pinky"),
    "left_hip": ("left_hip",),
    "right_hip": ("right_hip",),
    "left_knee": ("left_knee",),
    "right_knee": ("right_knee",),
    "left_foot": ("left_ankle", "left_heel", "left_foot_index"),
    "right_foot": ("right_ankle", "right_heel", "right_foot_index"),
}
_MEMBERS = {joint: [_INDEX[n] for n in names] for joint, names in JOINT_LANDMARKS.items()}
# MediaPipe's world frame -> ours: x and y flip (a half turn about the optical axis)
_AXES = np.array([-1.0, -1.0, 1.0])


@dataclass(frozen=True, eq=False)
class PoseEstimate:
    """One person's pose in one image, as the model gave it.

    `world`: (33, 3) metres, MediaPipe's frame (origin between the hips, x image-right, y down,
    z away); `pixels`: (33, 2) the landmarks in the image, x from its left edge, y from its top,
    in pixels (outside the image for a guessed one); `visibility`: (33,) in [0, 1]."""

    world: FloatArray
    pixels: FloatArray
    visibility: FloatArray
    width: int
    height: int


def _joint_means(points: FloatArray) -> dict[str, FloatArray]:
    return {joint: points[idx].mean(axis=0) for joint, idx in _MEMBERS.items()}


def joint_confidence(pose: PoseEstimate) -> dict[str, float]:
    """Each joint's confidence: the least visibility of the landmarks it is made of."""
    vis = np.clip(pose.visibility, 0.0, 1.0)
    return {joint: float(vis[idx].min()) for joint, idx in _MEMBERS.items()}


def kinect_joints(pose: PoseEstimate) -> dict[str, tuple[tuple[float, float, float], float]]:
    """Joint -> (position in metres, torso at the origin, OpenNI's axes; confidence)."""
    joints = _joint_means(pose.world * _AXES)
    torso = joints["torso"]
    confidence = joint_confidence(pose)
    out: dict[str, tuple[tuple[float, float, float], float]] = {}
    for name, xyz in joints.items():
        x, y, z = (float(v) for v in xyz - torso)
        out[name] = ((x, y, z), confidence[name])
    return out


def pixel_joints(pose: PoseEstimate) -> dict[str, tuple[float, float]]:
    """Joint -> where it is in the image (pixels, from the top-left corner), made of the same
    landmarks as `kinect_joints`' joint of that name."""
    return {name: (float(p[0]), float(p[1])) for name, p in _joint_means(pose.pixels).items()}
