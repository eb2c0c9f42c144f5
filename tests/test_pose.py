"""The pose source's library (cognition.pose) on real images of people: MediaPipe's landmarks
become the Kinect-like skeleton the gesture models read (names, OpenNI's axes, metres, the torso
at the origin, per-joint confidence), and each joint is where the person is in the image."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from pose_media import (
    CAMERAMAN_RIGHT_HAND,
    CARPHONE_FACE,
    cameraman,
    carphone,
    grace_hopper,
    read_rgb,
)

from beyond_self.cognition.gestures.synthetic import JOINTS
from beyond_self.cognition.pose import PoseEstimate, kinect_joints, pixel_joints
from beyond_self.cognition.pose.estimator import PoseEstimator
from beyond_self.cognition.pose.skeleton import LANDMARKS
from beyond_self.cognition.pose.video import Video
from beyond_self.core.errors import InputError

FRAMES = 40  # of carphone's 120: enough to track, cheap enough for every run


@pytest.fixture(scope="module")
def stills() -> Iterator[PoseEstimator]:
    with PoseEstimator(video=False) as estimator:
        yield estimator


@pytest.fixture(scope="module")
def carphone_poses() -> list[PoseEstimate | None]:
    poses: list[PoseEstimate | None] = []
    with PoseEstimator(video=True) as estimator, Video(carphone()) as video:
        for frame in video.frames():
            poses.append(estimator.estimate(frame.rgb))
            if len(poses) == FRAMES:
                break
    return poses


def test_a_video_gives_a_person_in_nearly_every_frame_where_he_is(
    carphone_poses: list[PoseEstimate | None],
) -> None:
    found = [p for p in carphone_poses if p is not None]
    assert len(found) >= 0.9 * FRAMES, f"a person in {len(found)} of {FRAMES} frames"
    x0, y0, x1, y1 = CARPHONE_FACE
    for pose in found:
        assert (pose.width, pose.height) == (176, 144)
        u, v = pixel_joints(pose)["head"]
        assert x0 <= u <= x1 and y0 <= v <= y1, f"head at ({u:.0f}, {v:.0f}), off his face"
        # every joint the model sees (not a guess below the frame) is inside the image
        for name, (_, confidence) in kinect_joints(pose).items():
            if confidence >= 0.5:
                u, v = pixel_joints(pose)[name]
                assert 0 <= u <= 176 and 0 <= v <= 144, f"{name} seen at ({u:.0f}, {v:.0f})"


def test_the_skeleton_is_a_person_in_metres_on_the_depth_sensors_axes(
    carphone_poses: list[PoseEstimate | None],
) -> None:
    for pose in (p for p in carphone_poses if p is not None):
        joints = {name: np.array(xyz) for name, (xyz, _) in kinect_joints(pose).items()}
        assert set(JOINTS) <= set(joints), "the joints the gesture models read"
        assert np.allclose(joints["torso"], 0.0), "centred on the torso"
        shoulders = float(np.linalg.norm(joints["left_shoulder"] - joints["right_shoulder"]))
        assert 0.25 <= shoulders <= 0.5, f"shoulders {shoulders:.2f} m apart"
        assert 0.1 <= joints["neck"][1] <= 0.4, "the neck above the torso (y up)"
        assert 0.05 <= joints["head"][1] - joints["neck"][1] <= 0.35, "the head above the neck"
        assert joints["left_hip"][1] < 0 and joints["right_hip"][1] < 0, "the hips below"
        # OpenNI's mirror: the person's right on +x
        assert joints["right_shoulder"][0] > 0.1 > -0.1 > joints["left_shoulder"][0]
        for name, xyz in joints.items():
            assert np.linalg.norm(xyz) < 1.2, f"{name} {xyz} m from the torso"


def test_a_still_gives_the_hand_where_the_persons_hand_is(stills: PoseEstimator) -> None:
    pose = stills.estimate(read_rgb(cameraman()))
    assert pose is not None
    joints = kinect_joints(pose)
    pixels = pixel_joints(pose)
    wrist = pose.pixels[LANDMARKS.index("right_wrist")]
    x0, y0, x1, y1 = CAMERAMAN_RIGHT_HAND
    for what, (u, v) in (("wrist", wrist), ("hand", pixels["right_hand"])):
        assert x0 <= u <= x1 and y0 <= v <= y1, f"right {what} at ({u:.0f}, {v:.0f})"
    assert joints["right_hand"][1] > 0.5, "the hand is seen"
    # the skeleton in metres, seen from the camera (x, y flipped back, a scale and a shift fitted
    # over all joints), puts the hand where the image has it: the axes and units agree
    names = sorted(joints)
    metres = np.array([joints[n][0][:2] for n in names]) * np.array([-1.0, -1.0])
    image = np.array([pixels[n] for n in names])
    design = np.column_stack([metres.ravel(), np.tile(np.eye(2), (len(names), 1))])
    (scale, du, dv), *_ = np.linalg.lstsq(design, image.ravel(), rcond=None)
    assert scale > 0
    hand = np.array(joints["right_hand"][0][:2]) * -1.0 * scale + (du, dv)
    body = float(np.ptp(image[:, 1]))
    error = float(np.linalg.norm(hand - pixels["right_hand"]))
    assert error < 0.15 * body, f"the 3-D hand is {error:.0f} px from the image's ({body:.0f})"


def test_a_joint_out_of_the_picture_has_a_low_confidence(stills: PoseEstimator) -> None:
    pose = stills.estimate(read_rgb(grace_hopper()))
    assert pose is not None
    joints = kinect_joints(pose)
    assert joints["head"][1] > 0.9 and joints["neck"][1] > 0.9
    assert joints["right_hand"][1] < 0.3 and joints["left_hand"][1] < 0.3, "hands below the frame"
    assert pixel_joints(pose)["right_hand"][1] > pose.height, "guessed below the frame"


def test_no_person_no_pose(stills: PoseEstimator) -> None:
    assert stills.estimate(np.full((120, 160, 3), 90, np.uint8)) is None
    with pytest.raises(InputError, match="valid: \\(height, width, 3\\) RGB"):
        stills.estimate(np.zeros((4, 4), np.uint8))


def test_a_video_that_is_not_one_says_so(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="does not exist"):
        Video(tmp_path / "none.mp4")
    bad = tmp_path / "bad.mp4"
    bad.write_text("not a video\n")
    with pytest.raises(InputError, match=r"cannot be read|holds no frame"), Video(bad) as video:
        list(video.frames())
    with pytest.raises(InputError, match="camera 63 does not open"):
        Video(camera=63)
