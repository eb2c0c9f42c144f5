"""End-to-end latency of the pipeline, next to a raw Zenoh hop measured in the same run.

What is measured: the gesture streamer, the affordance reasoner and the description generator
run as separate processes on loopback (as `beyond up` runs them). This script publishes a
synthetic skeleton stream of 100+ gestures; for each gesture, the clock starts when the frame that
lets the segmenter decide the gesture is over is published (computed offline with the same
segmenter) and stops when the gesture's final description arrives. Between gestures the script
waits for the description, so each figure is one uncongested pass through
streamer → reasoner → describer (4 bus hops: frame, posterior + end event, words, description).
The object segmenter is not on this path: its per-gesture analysis is timed separately below,
because it runs on camera frames this benchmark does not render.

Raw reference: a raw zenoh-python ping-pong with a child process (payload bytes, no decoding),
one-way = round trip / 2. Throughput: frames per second one gesture streamer process sustains
(frames published as fast as the bus takes them, counted on its output), and what that means in
simultaneous 30 fps humans. Ends with one line of JSON.
"""

from __future__ import annotations

import asyncio
import json
import os
import statistics
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import schemas as s  # noqa: E402
from cognition.gestures import GestureSegmenter, synthesize_continuous  # noqa: E402
from runtime.bus import Bus  # noqa: E402
from runtime.config import BusConfig  # noqa: E402
from services.launcher import service_env, start_service, stop_services  # noqa: E402

GESTURES = int(os.environ.get("BENCH_GESTURES", "100"))
PORT = 17800 + os.getpid() % 1000
CHUNK = 256  # frames per burst in the throughput pass (the streamer's queue holds 1024)


def stream_frames(seed: int) -> tuple[list[s.SkeletonFrame], list[int]]:
    """Skeleton frames of GESTURES gestures and the indices of the frames that end them."""
    stream = synthesize_continuous(GESTURES, seed=seed)
    frames = []
    for i in range(stream.n_frames):
        joints = {
            n: s.Joint(position=(float(p[i, 0]), float(p[i, 1]), float(p[i, 2])))
            for n, p in stream.joints.items()
        }
        header = s.Header(version=1, source="bench", seq=i, stamp=10**18 + i * 33_333_333)
        frames.append(s.SkeletonFrame(header=header, frame=i + 1, joints=joints))
    seg = GestureSegmenter()
    triggers = [i for i, x in enumerate(stream.features()) if seg.push(x) is not None]
    return frames, triggers


def raw_hop_us(config: BusConfig, n: int = 2000) -> float:
    """Median one-way latency of raw zenoh-python (ping-pong with a child process)."""
    import zenoh

    from runtime.config import zenoh_config

    child = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(f"""
            import sys, time, zenoh
            sys.path.insert(0, {str(REPO)!r})
            from runtime.config import BusConfig, zenoh_config
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


async def pipeline_latency(config: BusConfig) -> tuple[list[float], float, float]:
    env = service_env(config, {"BEYOND_LOG_FORMAT": "text", "BEYOND_LOG_LEVEL": "WARNING"})
    procs = [
        await start_service("gestures", env),
        await start_service("reasoner", env, options={"objects": False}),
        await start_service("describer", env),
    ]
    frames, triggers = stream_frames(seed=7)
    latencies: list[float] = []
    try:
        with Bus.open(config) as bus:
            await bus.wait_alive(bus.keys.alive("*"), count=3, timeout=60)
            out = bus.subscribe(bus.keys.description, s.Description)
            predictions = bus.subscribe(bus.keys.affordance, s.AffordancePrediction)
            pub = bus.publisher(bus.keys.skeleton, s.SkeletonFrame)
            await pub.wait_matching(timeout=30)
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
        await stop_services(procs)
    return latencies, len(frames) / wall, len(frames) / 30.0


async def _consumed(bus: Bus, health_key: str) -> int:
    replies = await bus.query(health_key, s.ServiceHealth, timeout=2.0)
    health = replies[0].message
    if health.dropped:
        raise RuntimeError(f"the streamer dropped {health.dropped} frames: chunk too big")
    return health.messages_in


def vision_analysis_ms() -> float:
    """Median time the object segmenter spends analysing one gesture's camera frames."""
    from cognition.vision.clusters import ClusterModel
    from cognition.vision.pipeline import analyse_frames
    from cognition.vision.tabletop import simulate_experiment

    clusters = ClusterModel.load()
    rng = np.random.default_rng(0)
    times = []
    for action in ("tap", "grasp", "touch"):
        exp = simulate_experiment(action, "yellow", "circle", "small", rng)
        t0 = time.perf_counter()
        analyse_frames(exp.frames, exp.fps, clusters)
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times)


def main() -> None:
    config = BusConfig(robot=f"bench{os.getpid()}", port=PORT)
    hop = raw_hop_us(config)
    latencies, fps, _ = asyncio.run(pipeline_latency(config))
    lat = np.array(latencies)
    median, p99 = float(np.median(lat)), float(np.percentile(lat, 99))
    vision = vision_analysis_ms()
    figures = {
        "bench": "pipeline",
        "gestures": len(latencies),
        "latency_ms_median": round(median, 3),
        "latency_ms_p99": round(p99, 3),
        "raw_zenoh_hop_us_median": round(hop, 1),
        "p99_in_raw_hops": round(p99 * 1e3 / hop, 1),
        "goal_p99_under_30ms": bool(p99 < 30.0),
        "goal_p99_under_5_raw_hops": bool(p99 * 1e3 < 5 * hop),
        "streamer_frames_per_s": round(fps, 1),
        "simultaneous_30fps_humans_per_streamer": round(fps / 30.0, 1),
        "vision_analysis_ms_per_gesture": round(vision, 1),
    }
    print(f"gestures measured: {len(latencies)}")
    print(f"end-to-end latency: median {median:.2f} ms, p99 {p99:.2f} ms "
          f"(raw Zenoh hop {hop:.0f} us: p99 = {p99 * 1e3 / hop:.0f} raw hops)")  # fmt: skip
    print(f"gesture streamer: {fps:.0f} frames/s = {fps / 30:.1f} simultaneous 30 fps humans")
    print(f"object segmenter per-gesture analysis (not on the path above): {vision:.0f} ms")
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
