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
from collections.abc import Callable
from pathlib import Path

from rich.console import Console

from beyond_self.cognition.pose.estimator import PoseEstimator
from beyond_self.cognition.pose.video import Video
from beyond_self.cognition.scene import EPOCH_NS
from beyond_self.commands import argtypes
from beyond_self.commands.terminal import progress_bar
from beyond_self.runtime.recording.person import PersonFrame, person_messages
from beyond_self.runtime.recording.writer import RecordingWriter
from beyond_self.schemas import Header, Message
from beyond_self.schemas.keys import DEFAULT_ROBOT, Keys

HELP = "turn a video of a person into a recording (skeleton from a pose model + the images)"

SOURCE = "video"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("video", type=Path, metavar="FILE", help="a video file (mp4, avi, ...)")
    argtypes.add_output(parser, "the recording to write (REC.mcap)", required=True)
    parser.add_argument(
        "--robot", default=DEFAULT_ROBOT, help=f"robot name in the keys (default {DEFAULT_ROBOT})"
    )


def run(args: argparse.Namespace) -> int:
    keys = Keys(args.robot)
    out = Path(args.output)
    partial = out.with_name(out.name + ".partial")  # the file appears whole, or not at all
    video = Video(args.video)
    seqs: dict[type[Message], int] = {}  # each stream numbered on its own

    def header_at(stamp: int) -> Callable[[type[Message]], Header]:
        def header(cls: type[Message]) -> Header:
            seq = seqs[cls] = seqs.get(cls, -1) + 1
            return cls.original_header(SOURCE, seq, stamp, chain=cls.type_name())

        return header

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
                pose = estimator.estimate(frame.rgb)
                person = PersonFrame(frame.index, frame.rgb, pose)
                for stream, message in person_messages(header_at(EPOCH_NS + frame.time_ns), person):
                    writer.write(keys.stream(stream), message)
                skeletons += pose is not None
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
