"""A camera robot's cost in the object segmenter: CPU per camera frame, by part, next to the
same path in the code before the cut (issue 51), measured in the same run.

    .venv/bin/python bench/camera.py [--runs N] [--reference COMMIT] [--save]

One robot's simulated scene (bench/pipeline.py's `vision_scene(1)`, robot 0 of bench/fleet.py's
camera case: skeleton at 30 Hz, 15 fps JPEG frames, `beyond simulate`) goes through the calls
the object segmenter makes per frame, each part's CPU summed over the frames: the frame decoded
(`image_from_message`); the gestures' windows (`ObjectWatch.camera`, then `catch_up` until
done, the gesture events found offline by the services' own tracker); the frame described by
the service's `FrameDescriber` (its worker process), as the segmenter's own CPU for the hand-off
and the worker's. Each run is a process of its own with one BLAS thread and the segmenter's
per-process set-up (`ObjectSegmenter.warm`), as a service has. The reference is the same script
run on the package of `--reference` (default: the commit before the cut), taken out of git into
a temporary folder, runs alternating with ours; figures are medians over the runs (each run's
spread is printed). Ends with one line of JSON; --save also writes it to
bench/results/camera.json as `result`, with the date, the machine and the provenance.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import datetime
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
REFERENCE = "413ba0f"  # main before the camera cut of issue 51
PARTS = ("decode", "windows", "describe_segmenter", "describe_worker")


def _children_cpu_s() -> float:
    """CPU seconds of this process's children so far (the describer's worker)."""
    total = 0.0
    for task in Path("/proc/self/task").iterdir():
        with contextlib.suppress(OSError):
            for pid in (task / "children").read_text().split():
                with contextlib.suppress(OSError):
                    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
                    total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return total


def measure(path: str) -> dict[str, Any]:
    """The per-frame parts (ms of CPU) of the scene at `path`, with whichever `beyond_self` this
    process imports (ours, or the reference's through PYTHONPATH)."""
    import beyond_self
    import beyond_self.schemas as s
    from beyond_self.cognition.episodes import Ended, GestureTracker, ObjectWatch, Started
    from beyond_self.cognition.gestures import extract_features
    from beyond_self.cognition.gestures.default_models import default_models
    from beyond_self.cognition.vision.clusters import ClusterModel
    from beyond_self.runtime.recording.images import image_from_message
    from beyond_self.runtime.recording.reader import read_recording
    from beyond_self.services.frame_describer import FrameDescriber
    from beyond_self.services.objects import ObjectSegmenter

    ObjectSegmenter.warm({})
    items = [item.message() for item in read_recording(Path(path))]
    tracker: GestureTracker[None] = GestureTracker(default_models())
    events: dict[int, list[Any]] = {}
    for i, msg in enumerate(items):
        if isinstance(msg, s.SkeletonFrame):
            j = msg.joints
            x = extract_features(j["right_hand"].position, j["torso"].position)[0]
            events[i] = list(tracker.push(msg.header.stamp, msg.frame, x, None))
    cpu = dict.fromkeys(PARTS, 0.0)
    clock = time.process_time
    watch: ObjectWatch[None] = ObjectWatch(ClusterModel.load(None))
    images = []
    for i, msg in enumerate(items):
        if isinstance(msg, s.SkeletonFrame):
            for ev in events[i]:
                if isinstance(ev, Started):
                    watch.started(ev.segment_id, ev.stamp, None)
                elif isinstance(ev, Ended):
                    watch.ended(ev.segment_id, ev.start_stamp, ev.end_stamp, msg.frame, None)
            watch.gestures_complete(msg.header.stamp)
            continue
        assert isinstance(msg, s.CompressedCameraFrame | s.CameraFrame)
        t = clock()
        image = image_from_message(msg)
        cpu["decode"] += clock() - t
        t = clock()
        watch.camera(msg.header.stamp, msg.header.seq, image)
        while watch.catch_up():
            pass
        cpu["windows"] += clock() - t
        images.append(image)

    async def describe_all() -> None:
        describer = FrameDescriber(None, 0)
        try:
            await describer.describe(images[0])  # the worker started and warm
            t, w = clock(), _children_cpu_s()
            for image in images:
                await describer.describe(image)
            cpu["describe_segmenter"] += clock() - t
            cpu["describe_worker"] += _children_cpu_s() - w
        finally:
            describer.close()

    asyncio.run(describe_all())
    n = len(images)
    parts = {k: round(1e3 * v / n, 3) for k, v in cpu.items()}
    return {"tree": str(Path(beyond_self.__file__).parent), "frames": n, "ms": parts}


def _run(path: Path, tree: Path | None) -> dict[str, Any]:
    """`measure` in a process of its own, on the package under `tree` (None: ours)."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    if tree is not None:
        env["PYTHONPATH"] = str(tree)
    out = subprocess.run(
        [sys.executable, __file__, "--measure", str(path)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    result: dict[str, Any] = json.loads(out.stdout.splitlines()[-1])
    return result


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--runs", type=int, default=3, help="runs of each, alternating (3)")
    parser.add_argument(
        "--reference", default=REFERENCE, help=f"the commit measured beside ours ({REFERENCE})"
    )
    parser.add_argument("--save", action="store_true", help="write bench/results/camera.json")
    parser.add_argument("--measure", help=argparse.SUPPRESS)  # a run's own process
    args = parser.parse_args()
    if args.measure:
        print(json.dumps(measure(args.measure)))
        return
    began, load = datetime.datetime.now(datetime.UTC), os.getloadavg()[0]
    sys.path.insert(0, str(REPO / "bench"))
    import results_file
    from pipeline import VISION_SCENE

    from beyond_self.cli import main as beyond

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        old = root / "reference"
        old.mkdir()
        archive = subprocess.run(
            ["git", "-C", str(REPO), "archive", args.reference, "beyond_self"],
            capture_output=True,
            check=True,
        ).stdout
        subprocess.run(["tar", "-x", "-C", str(old)], input=archive, check=True)
        scene = root / "scene.mcap"  # bench/pipeline.py's `vision_scene(1)`, kept as a file
        with contextlib.redirect_stdout(sys.stderr):
            assert beyond(["simulate", VISION_SCENE, "-o", str(scene), "--seed", "3"]) == 0
        runs: dict[str, list[dict[str, Any]]] = {"ours": [], "reference": []}
        for i in range(args.runs):
            for name, tree in (("reference", old), ("ours", None)):
                result = _run(scene, tree)
                runs[name].append(result)
                print(f"run {i + 1} {name:9} {json.dumps(result['ms'])}", file=sys.stderr)
    result = report(runs, args.reference)
    if args.save:
        results_file.save("camera", result, began, load)


def report(runs: dict[str, list[dict[str, Any]]], reference: str) -> dict[str, Any]:
    med = {
        name: {p: statistics.median(r["ms"][p] for r in rs) for p in PARTS}
        for name, rs in runs.items()
    }
    totals = {name: [sum(r["ms"].values()) for r in rs] for name, rs in runs.items()}
    print(f"{'ms of CPU per camera frame':28} {'reference':>10} {'ours':>8} {'ratio':>7}")
    for p in PARTS:
        ref, ours = med["reference"][p], med["ours"][p]
        print(f"{p:28} {ref:10.3f} {ours:8.3f} {ours / ref:7.2f}")
    ref_t, ours_t = statistics.median(totals["reference"]), statistics.median(totals["ours"])
    print(f"{'total':28} {ref_t:10.3f} {ours_t:8.3f} {ours_t / ref_t:7.2f}")
    for name, ts in totals.items():
        print(f"  {name}: totals of the runs {', '.join(f'{t:.2f}' for t in ts)} ms")
    frames = runs["ours"][0]["frames"]
    result = {
        "bench": "camera",
        "frames": frames,
        "runs": len(totals["ours"]),
        "reference": reference,
        "ms_per_frame": {k: round(v, 3) for k, v in med["ours"].items()},
        "reference_ms_per_frame": {k: round(v, 3) for k, v in med["reference"].items()},
        "total_ms": round(ours_t, 3),
        "reference_total_ms": round(ref_t, 3),
        "ratio": round(ours_t / ref_t, 3),
        "totals_ms": [round(t, 3) for t in totals["ours"]],
        "reference_totals_ms": [round(t, 3) for t in totals["reference"]],
    }
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
