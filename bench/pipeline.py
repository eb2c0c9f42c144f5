"""End-to-end latency of the pipeline, idle and under load, next to a raw Zenoh hop measured in
the same run; where the object segmenter's time goes per camera frame.

    .venv/bin/python bench/pipeline.py [--load N]

Every pass runs on an idle machine first; with `--load N` the bench then starts N processes
that spin on the CPU (`while True: pass`) and runs every pass again beside them, so both columns
come from one run. On this project's 2-core machine `--load 3` leaves the pipeline well under a
core.

No vision: the gesture streamer, the affordance reasoner and the description generator run as
separate processes on loopback (as `beyond up` runs them). This script publishes a synthetic
skeleton stream of 100+ gestures; for each gesture, the clock starts when the frame that lets
the segmenter decide the gesture is over is published (computed offline with the same
segmenter) and stops when the gesture's final description arrives. Between gestures the script
waits for the description, so each figure is one uncongested pass through
streamer → reasoner → describer (4 bus hops: frame, posterior + end event, words, description).

With vision: a simulated scene (skeleton at 30 Hz + 15 fps JPEG camera, `beyond simulate`) is
published at real time, as a live sensor would (nothing waits for the services), into the
gesture streamer, the object segmenter, the reasoner and the describer as processes (wall
clock: a live source, so the object segmenter may skip describing frames it cannot keep up
with; the count is printed). Per gesture, from the last input its description needs (the later
of the skeleton frame that ends it and the first camera frame after its end, found offline by
the same GestureTracker) to its final description; and its first anticipation (the affordance
prediction fused with the object seen at its start), from the last input it needs: the latest
of the skeleton frame its belief is about, the skeleton frame at which the segmenter announces
the gesture (it places the onset a few frames back, so that belief is computed only then) and
the first camera frame at or after the gesture's start (which decides its object); also from
the belief's frame alone, which includes the segmenter's look-back.

Stage costs: the object segmenter's work per camera frame, in this process, on simulated
320×240 and 640×480 JPEG frames with BLAS on one thread (as the services run): decoding, the
gestures' share (kept, and analysed in the window of a gesture under way, one step at a time as
the service does between messages: the longest step is how long a message may wait), the
frame's own objects (the table estimated from the frame), a gesture's start (its lead frames
queued, then analysed in steps) and its end (the effects from the frames analysed: one frame's
work), next to the 66.7 ms a 15 fps camera allows, and the batch analysis of the same gesture's
frames for reference.

Raw reference: a raw zenoh-python ping-pong with a child process (payload bytes, no decoding),
one-way = round trip / 2. Throughput (idle only): frames per second one gesture streamer process
sustains (frames published as fast as the bus takes them, counted on its output), and what that
means in simultaneous 30 fps humans. Ends with one line of JSON.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import statistics
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))  # busutil_net: the loaded machine the tests use too

from busutil_net import busy_loops  # noqa: E402

import beyond_self.schemas as s  # noqa: E402
from beyond_self.cognition.gestures import (  # noqa: E402
    GestureSegmenter,
    Segment,
    synthesize_continuous,
)
from beyond_self.runtime.bus.config import BusConfig  # noqa: E402
from beyond_self.runtime.bus.publisher import Publisher  # noqa: E402
from beyond_self.runtime.bus.session import Bus  # noqa: E402
from beyond_self.runtime.bus.subscription import Subscription  # noqa: E402
from beyond_self.services.deployment import Deployment  # noqa: E402

GESTURES = int(os.environ.get("BENCH_GESTURES", "100"))
PORT = 17800 + os.getpid() % 1000
VISION_REPEATS = int(os.environ.get("BENCH_VISION_REPEATS", "4"))  # x 6 gestures, real time
QUIET = {"BEYOND_LOG_FORMAT": "text", "BEYOND_LOG_LEVEL": "WARNING"}
CHUNK = 256  # frames per burst in the throughput pass (the streamer's queue holds 1024)


def stream_frames(seed: int, gestures: int = GESTURES) -> tuple[list[s.SkeletonFrame], list[int]]:
    """Skeleton frames of `gestures` gestures and the indices of the frames that end them."""
    stream = synthesize_continuous(gestures, seed=seed)
    frames = []
    rows = {n: p.tolist() for n, p in stream.joints.items()}  # floats, not numpy's per element
    for i in range(stream.n_frames):
        joints = {n: s.Joint(position=(r[i][0], r[i][1], r[i][2])) for n, r in rows.items()}
        header = s.Header(version=1, source="bench", seq=i, stamp=10**18 + i * 33_333_333)
        frames.append(s.SkeletonFrame(header=header, frame=i + 1, joints=joints))
    seg = GestureSegmenter()
    triggers = [i for i, x in enumerate(stream.features()) if isinstance(seg.push(x), Segment)]
    return frames, triggers


def raw_hop_us(config: BusConfig, n: int = 2000) -> float:
    """Median one-way latency of raw zenoh-python (ping-pong with a child process)."""
    import zenoh

    from beyond_self.runtime.bus.config import zenoh_config

    child = subprocess.Popen(
        [sys.executable, "-P", "-c", textwrap.dedent(f"""
            import sys, time, zenoh
            sys.path.append({str(REPO)!r})  # after the installed package, never before it
            from beyond_self.runtime.bus.config import BusConfig, zenoh_config
            s = zenoh.open(zenoh_config(BusConfig(robot={config.robot!r}, port={config.port})))
            pub = s.declare_publisher("bench/pong")
            sub = s.declare_subscriber("bench/ping", lambda x: pub.put(x.payload))
            print("ready", flush=True)
            sys.stdin.read()
        """)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert child.stdout is not None and child.stdout.readline().strip() == "ready"
    session = zenoh.open(zenoh_config(config))
    got: list[float] = []
    pending = {"t": 0.0}
    import threading

    done = threading.Event()

    def on_pong(_: object) -> None:
        got.append(time.perf_counter() - pending["t"])
        done.set()

    pong = session.declare_subscriber("bench/pong", on_pong)  # kept: dropping undeclares
    pub = session.declare_publisher("bench/ping")
    payload = bytes(64)
    while not pub.matching_status.matching:
        time.sleep(0.01)
    for _ in range(n):
        done.clear()
        pending["t"] = time.perf_counter()
        pub.put(payload)
        if not done.wait(2.0):
            raise RuntimeError("raw ping-pong: no pong within 2 s")
    pong.undeclare()
    session.close()
    child.kill()  # a zenoh session can hold the interpreter's exit; this is a throwaway echo
    child.wait(10)
    return statistics.median(got[100:]) / 2 * 1e6


async def pipeline_latency(
    config: BusConfig, throughput: bool = True
) -> tuple[list[float], float, float]:
    """Per gesture, ending frame -> final description (ms), without vision; with `throughput`
    also the frames per second the streamer sustains (else 0)."""
    names = ["gestures", "reasoner", "describer"]
    pipeline = Deployment(config, names, options={"reasoner": {"objects": False}}, env=QUIET)
    frames, triggers = stream_frames(seed=7)
    latencies: list[float] = []
    try:
        bus, out, (pub,) = await _feeding(pipeline, (SKELETON, s.SkeletonFrame))
        predictions = bus.subscribe(bus.keys.affordance, s.AffordancePrediction)
        trig = set(triggers)
        for i, frame in enumerate(frames):
            if i in trig:
                # let the pipeline catch up with the frames before (they were sent faster
                # than real time), so the clock measures one pass, not a backlog
                while (await predictions.recv(timeout=30)).message.frame < i:
                    pass
                t0 = time.perf_counter()
                pub.put(frame)
                await out.recv(timeout=30)
                latencies.append((time.perf_counter() - t0) * 1e3)
            else:
                pub.put(frame)
                if i % 16 == 0:
                    await asyncio.sleep(0)  # do not starve our own subscribers
        if not throughput:
            return latencies, 0.0, len(frames) / 30.0
        # throughput: the same stream again in chunks, each published as fast as the bus
        # takes it, then waiting until the streamer has consumed it (its health count), so
        # its input queue never overflows and nothing is dropped
        health_key = bus.keys.health("gestures")
        before = await _consumed(bus, health_key)
        t0 = time.perf_counter()
        for start in range(0, len(frames), CHUNK):
            for frame in frames[start : start + CHUNK]:
                pub.put(frame)
            target = before + min(start + CHUNK, len(frames))
            while await _consumed(bus, health_key) < target:
                await asyncio.sleep(0.002)
        wall = time.perf_counter() - t0
    finally:
        await pipeline.stop()
    return latencies, len(frames) / wall, len(frames) / 30.0


SKELETON, CAMERA = "skeleton", "camera_compressed"  # streams of schemas.keys.STREAMS


async def _feeding(
    pipeline: Deployment, *inputs: tuple[str, type[s.Message]]
) -> tuple[Bus, Subscription[s.Description], list[Publisher[Any]]]:
    """Start `pipeline`; its descriptions, and a publisher on each input stream, matched by the
    services that take it (what is sent from then on is received)."""
    bus = await pipeline.open()
    await pipeline.start()
    out = bus.subscribe(bus.keys.description, s.Description)
    publishers: list[Publisher[Any]] = [
        bus.publisher(bus.keys.stream(stream), cls) for stream, cls in inputs
    ]
    for pub in publishers:
        await pub.wait_matching(timeout=30)
    return bus, out, publishers


async def _consumed(bus: Bus, health_key: str) -> int:
    replies = await bus.query(health_key, s.ServiceHealth, timeout=2.0)
    health = replies[0].message
    if health.dropped:
        raise RuntimeError(f"the streamer dropped {health.dropped} frames: chunk too big")
    return health.messages_in


VISION_SCENE = (
    "tap:yellow:circle:small,grasp:blue:box:big,touch:green2:box:medium,"
    "tap:blue:box:medium,grasp:green1:circle:big,touch:yellow:circle:small"
)
FRAME_BUDGET_MS = 1e3 / 15  # a 15 fps camera's frame interval


def vision_scene(repeats: int, seed: int = 3, turn: int = 0) -> list[s.Message]:
    """The scene's messages in stamp order (skeleton and compressed camera frames); `turn`
    rotates the order of its gestures (another person's scene: bench/fleet.py)."""
    import tempfile

    from beyond_self.cli import main as beyond
    from beyond_self.runtime.recording.reader import read_recording

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "scene.mcap"
        gestures = VISION_SCENE.split(",")
        turn %= len(gestures)
        scene = ",".join((gestures[turn:] + gestures[:turn]) * repeats)
        assert beyond(["simulate", scene, "-o", str(path), "--seed", str(seed)]) == 0
        return [item.message() for item in read_recording(path)]


def scene_gestures(items: list[s.Message]) -> dict[int, tuple[int, int, int, int]]:
    """Per segment id, found offline by the services' own GestureTracker: (index of the skeleton
    message that announces its start, of the one that ends it, its start stamp, its end
    stamp). The start is announced when the segmenter is sure of it, at an onset a few frames
    back."""
    from beyond_self.cognition.episodes import Ended, GestureTracker, Started
    from beyond_self.cognition.gestures import extract_features
    from beyond_self.cognition.gestures.default_models import default_models

    tracker: GestureTracker[None] = GestureTracker(default_models())
    announced: dict[int, int] = {}
    found: dict[int, tuple[int, int, int, int]] = {}
    for i, msg in enumerate(items):
        if isinstance(msg, s.SkeletonFrame):
            j = msg.joints
            x = extract_features(j["right_hand"].position, j["torso"].position)[0]
            for ev in tracker.push(msg.header.stamp, msg.frame, x, None):
                if isinstance(ev, Started):
                    announced[ev.segment_id] = i
                elif isinstance(ev, Ended):
                    found[ev.segment_id] = (
                        announced[ev.segment_id],
                        i,
                        ev.start_stamp,
                        ev.end_stamp,
                    )
    return found


async def vision_latency(config: BusConfig, items: list[s.Message]) -> dict[str, Any]:
    """Publish `items` at real time into the four services; per gesture the description's and
    the first anticipation's latencies (ms), and the frames the object segmenter skipped."""
    gestures = scene_gestures(items)
    pipeline = Deployment(config, ["gestures", "objects", "reasoner", "describer"], env=QUIET)
    sent_at: list[float] = []
    described: dict[int, float] = {}
    anticipated: dict[int, tuple[float, int]] = {}  # segment -> (arrival, skeleton frame)
    frames = {"described": 0, "skipped": 0}
    try:
        bus, out, (skeleton, camera) = await _feeding(
            pipeline, (SKELETON, s.SkeletonFrame), (CAMERA, s.CompressedCameraFrame)
        )
        predictions = bus.subscribe(bus.keys.affordance, s.AffordancePrediction)
        objects = bus.subscribe(bus.keys.objects, s.DetectedObjects)

        async def receive() -> None:
            while len(described) < len(gestures):
                msg = (await out.recv(timeout=120)).message
                described.setdefault(msg.segment_id, time.perf_counter())

        async def watch_predictions() -> None:
            async for received in predictions:
                p = received.message
                if not p.final and p.segment_id not in anticipated:
                    anticipated[p.segment_id] = (time.perf_counter(), p.frame)

        async def count_objects() -> None:
            async for received in objects:
                frames["described"] += 1
                frames["skipped"] += received.message.skipped

        loop = asyncio.get_running_loop()
        receiver = loop.create_task(receive())
        watchers = [loop.create_task(watch_predictions()), loop.create_task(count_objects())]
        t0_wall, t0_stamp = loop.time(), items[0].header.stamp
        for msg in items:
            delay = t0_wall + (msg.header.stamp - t0_stamp) / 1e9 - loop.time()
            if delay > 0:
                await asyncio.sleep(delay)
            if isinstance(msg, s.SkeletonFrame):
                skeleton.put(msg)
            else:
                camera.put(msg)  # type: ignore[arg-type]
            sent_at.append(time.perf_counter())
        await asyncio.wait_for(receiver, 120)
        await asyncio.sleep(1.0)  # the last frames' objects
        for task in watchers:
            task.cancel()
    finally:
        await pipeline.stop()
    stamps = [m.header.stamp for m in items]
    cameras = [k for k, m in enumerate(items) if not isinstance(m, s.SkeletonFrame)]
    skeleton_at = {m.frame: k for k, m in enumerate(items) if isinstance(m, s.SkeletonFrame)}

    def first_camera(after: Callable[[int], bool]) -> int:
        return next(k for k in cameras if after(stamps[k]))

    description, anticipation, anticipation_input = [], [], []
    for segment_id, (announce, trigger, start, end) in sorted(gestures.items()):
        last_input = max(sent_at[trigger], sent_at[first_camera(lambda t, e=end: t > e)])
        description.append((described[segment_id] - last_input) * 1e3)
        arrival, frame = anticipated[segment_id]
        from_frame = sent_at[skeleton_at[frame]]
        decides_object = sent_at[first_camera(lambda t, b=start: t >= b)]
        anticipation.append((arrival - from_frame) * 1e3)
        needed = max(from_frame, sent_at[announce], decides_object)
        anticipation_input.append((arrival - needed) * 1e3)
    if os.environ.get("BENCH_VERBOSE"):
        for k, ms in enumerate(description, 1):
            print(
                f"gesture {k}: description {ms:.1f} ms, anticipation {anticipation[k - 1]:.1f} ms"
            )
    return {
        "description_ms": description,
        "anticipation_ms": anticipation,
        "anticipation_from_last_input_ms": anticipation_input,
        "camera_frames": len(cameras),
        **{f"frames_{k}": v for k, v in frames.items()},
    }


@contextlib.contextmanager
def timed(times: list[float]) -> Iterator[None]:
    """Append the block's duration (ms) to `times`."""
    t0 = time.perf_counter()
    yield
    times.append((time.perf_counter() - t0) * 1e3)


def stage_costs(width: int, height: int) -> dict[str, float]:
    """Where the object segmenter's time goes per camera frame at `width`×`height` (ms, median):
    three simulated gestures (tap, grasp, touch) as 15 fps JPEG frames, each through the
    service's path (`ObjectWatch`) with BLAS on one thread; the description of a frame also with
    BLAS's default threads, for reference."""
    from threadpoolctl import threadpool_limits

    from beyond_self.cognition.episodes import GestureEffects, ObjectWatch
    from beyond_self.cognition.vision.clusters import ClusterModel
    from beyond_self.cognition.vision.pipeline import analyse_frames
    from beyond_self.cognition.vision.tabletop import Camera, simulate_experiment
    from beyond_self.runtime.recording.images import image_from_message, message_from_image

    clusters = ClusterModel.load()
    rng = np.random.default_rng(0)
    stages = ("decode", "gestures", "step", "objects", "start", "end", "batch")
    stages += ("objects_default_blas",)
    t: dict[str, list[float]] = {k: [] for k in stages}
    step, t0 = round(1e9 / 15), 10**18
    lead = 4  # frames kept before the gesture's start (lead_s 0.3 s at 15 fps, and one)
    for action in ("tap", "grasp", "touch"):
        exp = simulate_experiment(
            action, "blue", "circle", "medium", rng, fps=15.0, camera=Camera(width, height)
        )
        header = s.Header(version=1, source="bench", seq=0, stamp=t0)
        jpegs = [message_from_image(header, f, "jpeg", quality=80) for f in exp.frames]
        watch: ObjectWatch[int] = ObjectWatch(clusters, fps=15.0)
        images = []
        with threadpool_limits(limits=1, user_api="blas"):
            for k, msg in enumerate(jpegs):
                with timed(t["decode"]):
                    image = image_from_message(msg)
                images.append(image)
                if k == lead:
                    with timed(t["start"]):
                        watch.started(1, t0 + k * step, 0)
                with timed(t["gestures"]):  # queued, then analysed one step at a time
                    watch.camera(t0 + k * step, k, image)
                    while True:
                        with timed(t["step"]):
                            more = watch.catch_up()
                        if not more:
                            t["step"].pop()  # the step that found nothing to do
                            break
                with timed(t["objects"]):
                    watch.describe(image)
            end = t0 + (len(jpegs) - 1) * step
            watch.ended(1, t0 + lead * step, end, len(jpegs), 0)
            with timed(t["end"]):
                effects = watch.camera(end + step, len(jpegs), images[-1])
            assert any(isinstance(e, GestureEffects) and e.analysis for e in effects), effects
            with timed(t["batch"]):
                analyse_frames(images, 15.0, clusters)
        for image in images[:: max(1, len(images) // 8)]:
            with timed(t["objects_default_blas"]):
                watch.describe(image)
    costs = {k: statistics.median(v) for k, v in t.items()}
    costs["gestures_p99"] = float(np.percentile(t["gestures"], 99))
    costs["step_max"] = max(t["step"])
    costs["objects_p99"] = float(np.percentile(t["objects"], 99))
    return costs


def run_passes(config: BusConfig, items: list[s.Message], throughput: bool) -> dict[str, Any]:
    """Every pass once, on the machine as it is (its load average before and after is kept:
    a shared machine is never quite idle)."""
    figures: dict[str, Any] = {"load_before": os.getloadavg()[0]}
    figures["raw_hop_us"] = raw_hop_us(config)
    latencies, fps, _ = asyncio.run(pipeline_latency(config, throughput))
    figures["no_vision_ms"] = latencies
    if throughput:
        figures["streamer_frames_per_s"] = fps
    figures["vision"] = asyncio.run(vision_latency(config, items))
    figures["stages"] = {f"{w}x{h}": stage_costs(w, h) for w, h in ((320, 240), (640, 480))}
    figures["load_after"] = os.getloadavg()[0]
    return figures


def _p(values: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values), q))


def report(column: str, f: dict[str, Any]) -> dict[str, Any]:
    """The figures of one column (idle or loaded) for the JSON line."""
    v = f["vision"]
    out: dict[str, Any] = {
        "machine_load_average": [round(f["load_before"], 2), round(f["load_after"], 2)],
        "raw_zenoh_hop_us_median": round(f["raw_hop_us"], 1),
        "no_vision_latency_ms_median": round(_p(f["no_vision_ms"], 50), 3),
        "no_vision_latency_ms_p99": round(_p(f["no_vision_ms"], 99), 3),
        "with_vision_gestures": len(v["description_ms"]),
        "with_vision_latency_ms_median": round(_p(v["description_ms"], 50), 3),
        "with_vision_latency_ms_p99": round(_p(v["description_ms"], 99), 3),
        "anticipation_ms_median": round(_p(v["anticipation_from_last_input_ms"], 50), 3),
        "anticipation_ms_p99": round(_p(v["anticipation_from_last_input_ms"], 99), 3),
        "anticipation_from_onset_frame_ms_p99": round(_p(v["anticipation_ms"], 99), 3),
        "camera_frames": v["camera_frames"],
        "camera_frames_described": v["frames_described"],
        "camera_frames_skipped": v["frames_skipped"],
    }
    for size, costs in f["stages"].items():
        for stage, ms in costs.items():
            out[f"segmenter_{size}_{stage}_ms"] = round(ms, 2)
    goal = 33.0 if column == "idle" else 100.0
    out[f"goal_with_vision_p99_under_{goal:.0f}ms"] = bool(out["with_vision_latency_ms_p99"] < goal)
    if column == "loaded":
        out["goal_anticipation_p99_under_100ms"] = bool(out["anticipation_ms_p99"] < 100.0)
    return {f"{column}_{k}": value for k, value in out.items()}


def print_table(columns: dict[str, dict[str, Any]]) -> None:
    names = list(columns)
    print(f"{'':58s}" + "".join(f"{n:>22s}" for n in names))

    def row(label: str, cell: Callable[[dict[str, Any]], str]) -> None:
        print(f"{label:58s}" + "".join(f"{cell(columns[n]):>22s}" for n in names))

    def pct(values: list[float]) -> str:
        return f"{_p(values, 50):.1f} / {_p(values, 99):.1f}"

    row(
        "machine's load average, before / after the passes",
        lambda f: f"{f['load_before']:.1f} / {f['load_after']:.1f}",
    )
    row("raw Zenoh hop, one way (us)", lambda f: f"{f['raw_hop_us']:.0f}")
    row(
        "no vision: ending frame -> description, ms (median / p99)",
        lambda f: pct(f["no_vision_ms"]),
    )
    row(
        "vision: last input -> description, ms (median / p99)",
        lambda f: pct(f["vision"]["description_ms"]),
    )
    row(
        "vision: last input -> first anticipation, ms (median / p99)",
        lambda f: pct(f["vision"]["anticipation_from_last_input_ms"]),
    )
    row(
        "  from its belief's frame (the onset, looked back to), ms",
        lambda f: pct(f["vision"]["anticipation_ms"]),
    )
    row(
        "camera frames described / skipped (live)",
        lambda f: f"{f['vision']['frames_described']} / {f['vision']['frames_skipped']}",
    )
    for size in ("320x240", "640x480"):
        print(f"object segmenter per camera frame at {size} (ms, median; 15 fps allows "
              f"{FRAME_BUDGET_MS:.1f})")  # fmt: skip
        stages = (
            ("decode (JPEG)", "decode"),
            ("for the gestures (kept, analysed in a gesture's window)", "gestures"),
            ("  longest step between two messages (max)", "step_max"),
            ("its own objects (table estimated per frame)", "objects"),
            ("  the same with BLAS's default threads", "objects_default_blas"),
            ("a gesture's start (its lead frames queued)", "start"),
            ("a gesture's end (effects: one frame)", "end"),
            ("  batch analysis of its frames, for reference", "batch"),
        )
        for label, key in stages:
            row(f"  {label}", lambda f, k=key, z=size: f"{f['stages'][z][k]:.2f}")
        row(
            "  all of a frame (decode + gestures + objects) / budget",
            lambda f, z=size: "{:.0f}%".format(
                100
                * sum(f["stages"][z][k] for k in ("decode", "gestures", "objects"))
                / FRAME_BUDGET_MS
            ),
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--load", type=int, default=0, metavar="N", help="busy-looping processes")
    args = parser.parse_args()
    config = BusConfig(robot=f"bench{os.getpid()}", port=PORT)
    items = vision_scene(VISION_REPEATS)
    columns = {"idle": run_passes(config, items, throughput=True)}
    if args.load:
        with busy_loops(args.load):
            columns["loaded"] = run_passes(config, items, throughput=False)
    print(f"gestures: {len(columns['idle']['no_vision_ms'])} without vision, "
          f"{len(columns['idle']['vision']['description_ms'])} with vision at real time"
          + (f"; loaded: {args.load} busy-looping processes beside the pipeline" if args.load
             else ""))  # fmt: skip
    print_table(columns)
    fps = columns["idle"]["streamer_frames_per_s"]
    print(f"gesture streamer: {fps:.0f} frames/s = {fps / 30:.1f} simultaneous 30 fps humans")
    figures: dict[str, Any] = {"bench": "pipeline", "load": args.load}
    figures["streamer_frames_per_s"] = round(fps, 1)
    figures["simultaneous_30fps_humans_per_streamer"] = round(fps / 30.0, 1)
    for column, f in columns.items():
        figures.update(report(column, f))
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
