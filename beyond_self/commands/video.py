"""`beyond video FILE -o REC.mcap`: a video of a person -> a recording the pipeline plays.

Every frame goes through the pose model (cognition.pose, the `camera` extra) in order; a frame
with a person gives a skeleton frame (the Kinect-like joints the gesture models read, in
metres, torso at the origin, with per-joint confidence), and every frame is recorded as the
person's camera (JPEG, `sensors/person/compressed`), both stamped with the frame's own time in
the video from a fixed epoch (cognition.scene's). So the same video always gives the same
bytes, and `beyond analyse`, `beyond up --recording`, `replay` and Foxglove work on it as on
any recording. A video with nobody in it is recorded (its images) and said: "no person seen".
"""

from __future__ import annotations

import argparse
import contextlib
import os
from pathlib import Path

from rich.console import Console

from beyond_self.cognition.pose.estimator import PoseEstimator
from beyond_self.cognition.pose.video import Video
from beyond_self.cognition.scene import EPOCH_NS
from beyond_self.commands import argtypes
from beyond_self.commands.terminal import progress_bar
from beyond_self.runtime.recording_writer import RecordingWriter
from beyond_self.schemas import CompressedCameraFrame, Header, SkeletonFrame
from beyond_self.schemas.keys import DEFAULT_ROBOT, Keys
from beyond_self.services.pose_source import joints_of, person_image, pose_joints

HELP = "turn a video of a person into a recording (skeleton from a pose model + the images)"

SOURCE = "video"
SKELETON_FRAME = "person"  # the skeleton's frame: the torso at the origin, OpenNI's axes


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("video", type=Path, metavar="FILE", help="a video file (mp4, avi, ...)")
    parser.add_argument(
        "-o",
        "--output",
        type=argtypes.output_file,
        required=True,
        metavar="REC.mcap",
        help="the recording to write",
    )
    parser.add_argument(
        "--robot", default=DEFAULT_ROBOT, help=f"robot name in the keys (default {DEFAULT_ROBOT})"
    )


def _header(seq: int, stamp: int, stream: str, version: int) -> Header:
    return Header(
        version=version,
        source=SOURCE,
        seq=seq,
        stamp=stamp,
        correlation=f"{SOURCE}/{stream}/{seq}",
    )


def run(args: argparse.Namespace) -> int:
    keys = Keys(args.robot)
    out = Path(args.output)
    partial = out.with_name(out.name + ".partial")  # the file appears whole, or not at all
    video = Video(args.video)
    frames = skeletons = 0
    console = Console(stderr=True)
    try:
        with (
            video,
            PoseEstimator(video=True) as estimator,
            progress_bar(console) as progress,
            RecordingWriter(partial, metadata=_metadata(args, video)) as writer,
        ):
            task = progress.add_task(f"pose of {args.video.name}", total=video.frame_count)
            for frame in video.frames():
                stamp = EPOCH_NS + frame.time_ns
                pose = estimator.estimate(frame.rgb)
                if pose is not None:
                    joints = joints_of(pose_joints(pose))
                    header = _header(skeletons, stamp, "skeleton", SkeletonFrame.VERSION)
                    skeleton = SkeletonFrame(
                        header=header,
                        frame=frame.index + 1,
                        joints=joints,
                        frame_id=SKELETON_FRAME,
                    )
                    writer.write(keys.skeleton, skeleton)
                    skeletons += 1
                image = person_image(
                    _header(frame.index, stamp, "camera", CompressedCameraFrame.VERSION), frame.rgb
                )
                writer.write(keys.person_camera, image)
                frames += 1
                progress.advance(task)
        os.replace(partial, out)
    finally:
        with contextlib.suppress(FileNotFoundError):
            partial.unlink()
    seconds = (frames / video.fps) if frames else 0.0
    size = out.stat().st_size / 1e6
    if skeletons == 0:
        print(f"{out}: no person seen in {args.video} ({frames} frames, {seconds:.1f} s)")
        return 0
    print(
        f"{out}: {frames} frames ({seconds:.1f} s at {video.fps:.2f} fps), a person in "
        f"{skeletons} ({100 * skeletons / frames:.0f}%; no person in {frames - skeletons}), "
        f"{size:.2f} MB"
    )
    return 0


def _metadata(args: argparse.Namespace, video: Video) -> dict[str, str]:
    return {
        "generator": "beyond video",
        "video": args.video.name,
        "fps": f"{video.fps:.6g}",
        "robot": args.robot,
        "epoch_ns": str(EPOCH_NS),
        "pose_model": "mediapipe 0.10.14 BlazePose full (model_complexity 1)",
    }
