"""Bus overhead: raw zenoh-python pub/sub next to the runtime's typed pub/sub, and replay speed.

Two processes on loopback (this one publishes, a child subscribes), for a skeleton frame (15
joints, about 0.9 kB of msgpack) and a 320x240 rgb8 camera frame (about 230 kB):
- one-way latency, median and p99: messages paced at a fixed rate, each carrying the sender's
  CLOCK_MONOTONIC time (shared by all processes on Linux); measured when the receiver's code
  gets the message (raw: in the Zenoh callback; ours: when `async for` yields the decoded
  message on the event loop);
- throughput: a burst sent as fast as the sender can (reliable, so nothing is dropped), rate at
  which the receiver gets them.
Raw sends pre-built bytes of the same size as ours; ours encodes each message (msgspec) and
decodes it on receipt, as a service does.
Then replay of a 10 s recording (skeleton and camera at 30 Hz) as fast as possible into a
subscriber: speed as a multiple of real time (goal >= 50x).
Ends with one JSON line holding every figure.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import zenoh  # noqa: E402

import schemas as s  # noqa: E402
from runtime.bus import Bus  # noqa: E402
from runtime.config import BusConfig, zenoh_config  # noqa: E402

KINDS = {
    # kind: (latency messages, pacing Hz, throughput messages)
    "skeleton": (2000, 1000.0, 30000),
    "camera": (300, 200.0, 1500),
}
JOINTS = [
    "head", "neck", "torso", "shoulder_left", "elbow_left", "hand_left", "shoulder_right",
    "elbow_right", "hand_right", "hip_left", "knee_left", "foot_left", "hip_right", "knee_right",
    "foot_right",
]  # fmt: skip
CAMERA = bytes((x * 31 + y) % 256 for y in range(240) for x in range(320 * 3))


def make_message(kind: str, seq: int, stamp: int) -> s.Message:
    header = s.Header(version=1, source="bench", seq=seq, stamp=stamp, correlation=f"bench/{seq}")
    if kind == "skeleton":
        joints = {
            n: s.Joint((0.123456 + i, -0.654321 * i, 2.000001 + seq % 7), 1.0)
            for i, n in enumerate(JOINTS)
        }
        return s.SkeletonFrame(header=header, frame=seq, joints=joints)
    return s.CameraFrame.build(header, 320, 240, CAMERA)


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


# --- receiving side (child process) ---------------------------------------------------------


def receive_raw(config: BusConfig, kind: str, n: int) -> dict[str, object]:
    import threading

    session = zenoh.open(zenoh_config(config))
    key = f"bench/{config.robot}/{kind}"
    lat: list[int] = []
    times: list[int] = []
    done = threading.Event()
    n_lat = KINDS[kind][0]

    def on_sample(sample: zenoh.Sample) -> None:
        now = time.monotonic_ns()
        data = sample.payload.to_bytes()
        seq = int.from_bytes(data[:8], "little")
        if seq < n_lat:
            lat.append(now - int.from_bytes(data[8:16], "little"))
        else:
            times.append(now)
        if len(lat) + len(times) >= n:
            done.set()

    sub = session.declare_subscriber(key, on_sample)
    token = session.liveliness().declare_token(f"bench/{config.robot}/ready")
    done.wait(120)
    token.undeclare()
    sub.undeclare()
    session.close()
    return {"latency_ns": lat, "times_ns": times}


def receive_typed(config: BusConfig, kind: str, n: int) -> dict[str, object]:
    cls = s.SkeletonFrame if kind == "skeleton" else s.CameraFrame
    n_lat = KINDS[kind][0]

    async def go() -> dict[str, object]:
        with Bus.open(config) as bus:
            sub = bus.subscribe(f"bench/{config.robot}/{kind}", cls, maxsize=1 << 17)
            bus.declare_token(f"bench/{config.robot}/ready")
            lat: list[int] = []
            times: list[int] = []
            while len(lat) + len(times) < n:
                try:
                    received = await sub.recv(timeout=60)
                except TimeoutError:
                    break
                now = time.monotonic_ns()
                header = received.message.header
                if header.seq < n_lat:
                    lat.append(now - header.stamp)
                else:
                    times.append(now)
            return {"latency_ns": lat, "times_ns": times, "dropped": sub.dropped}

    return asyncio.run(go())


# --- sending side ---------------------------------------------------------------------------


def run_pair(mode: str, kind: str) -> dict[str, float]:
    n_lat, hz, n_thr = KINDS[kind]
    config = BusConfig(robot=f"b{os.getpid()}{mode}{kind}", port=free_port())
    child = subprocess.Popen(
        [sys.executable, __file__, "--receive", mode, kind, str(config.port), config.robot],
        stdout=subprocess.PIPE,
        text=True,
    )
    session = zenoh.open(zenoh_config(config))
    key = f"bench/{config.robot}/{kind}"
    ready = session.liveliness().declare_subscriber(f"bench/{config.robot}/ready", history=True)
    ready.handler.recv()  # the child's subscriber is declared before its token
    size_probe = len(s.encode(make_message(kind, 0, 0)))
    if mode == "raw":
        pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
        pad = bytes(size_probe - 16)

        def send(seq: int) -> None:
            pub.put(seq.to_bytes(8, "little") + time.monotonic_ns().to_bytes(8, "little") + pad)

        # pre-built payloads for the burst: raw Zenoh has nothing to encode
        burst = [i.to_bytes(8, "little") + bytes(8) + pad for i in range(n_lat, n_lat + n_thr)]

        def send_burst() -> None:
            for payload in burst:
                pub.put(payload)

    else:
        cls = s.SkeletonFrame if kind == "skeleton" else s.CameraFrame
        typed = Bus(session, config).publisher(key, cls)
        while not typed.matching():
            time.sleep(0.01)

        def send(seq: int) -> None:
            typed.put(make_message(kind, seq, time.monotonic_ns()))

        messages = [make_message(kind, i, 0) for i in range(n_lat, n_lat + n_thr)]

        def send_burst() -> None:
            for message in messages:
                typed.put(message)

    period = 1.0 / hz
    next_at = time.perf_counter()
    for seq in range(n_lat):
        send(seq)
        next_at += period
        while (delay := next_at - time.perf_counter()) > 0:
            time.sleep(delay)
    t0 = time.monotonic_ns()
    send_burst()
    out, _ = child.communicate(timeout=180)
    session.close()
    result = json.loads(out.strip().splitlines()[-1])
    lat = sorted(result["latency_ns"])
    times = result["times_ns"]
    received = len(times)
    span = (max(times) - t0) / 1e9 if times else float("nan")
    return {
        "bytes": size_probe,
        "latency_median_us": statistics.median(lat) / 1e3,
        "latency_p99_us": lat[min(len(lat) - 1, int(0.99 * len(lat)))] / 1e3,
        "throughput_msgs_per_s": received / span,
        "throughput_mb_per_s": received * size_probe / span / 1e6,
        "received": received,
        "sent": n_thr,
    }


def replay_speed() -> dict[str, float]:
    from runtime.recording import RecordingWriter
    from runtime.replay import replay

    config = BusConfig(robot=f"r{os.getpid()}", port=free_port())
    keys = s.Keys(config.robot)
    start = 1_700_000_000_000_000_000
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.mcap"
        with RecordingWriter(path) as writer:
            for i in range(300):  # 10 s at 30 Hz
                stamp = start + i * 33_333_333
                skel = make_message("skeleton", i, stamp)
                writer.write(keys.skeleton, skel)
                header = s.Header(version=1, source="cam", seq=i, stamp=stamp + 1)
                writer.write(keys.camera, s.CameraFrame.build(header, 320, 240, CAMERA))
        size = path.stat().st_size

        async def go() -> dict[str, float]:
            results: dict[str, float] = {"recording_bytes": size}
            with Bus.open(config) as bus, Bus.open(config) as listener:
                for label, topics in (("skeleton", [keys.skeleton]), ("all", None)):
                    sub = listener.subscribe_raw(keys.everything, maxsize=1 << 16)
                    probe = bus.publisher(keys.skeleton, s.SkeletonFrame)
                    await probe.wait_matching(10)
                    expected = 300 if topics else 600
                    t0 = time.perf_counter()
                    stats = await replay(bus, path, rate=None, topics=topics)
                    for _ in range(expected):
                        await sub.recv(timeout=30)
                    wall = time.perf_counter() - t0
                    sub.close()
                    probe.close()
                    results[f"replay_{label}_messages"] = stats.messages
                    results[f"replay_{label}_speed_x_realtime"] = stats.span_s / wall
            return results

        return asyncio.run(go())


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--receive", nargs=4, metavar=("MODE", "KIND", "PORT", "ROBOT"))
    args = parser.parse_args()
    if args.receive:
        mode, kind, port, robot = args.receive
        config = BusConfig(robot=robot, port=int(port))
        n = KINDS[kind][0] + KINDS[kind][2]
        result = (receive_raw if mode == "raw" else receive_typed)(config, kind, n)
        print(json.dumps(result))
        return 0

    figures: dict[str, float] = {}
    for kind in KINDS:
        row = {}
        for mode in ("raw", "typed"):
            r = run_pair(mode, kind)
            row[mode] = r
            for name, value in r.items():
                figures[f"{kind}_{mode}_{name}"] = round(value, 3)
        lat_ratio = row["typed"]["latency_median_us"] / row["raw"]["latency_median_us"]
        p99_ratio = row["typed"]["latency_p99_us"] / row["raw"]["latency_p99_us"]
        thr_ratio = row["typed"]["throughput_msgs_per_s"] / row["raw"]["throughput_msgs_per_s"]
        figures[f"{kind}_latency_ratio"] = round(lat_ratio, 3)
        figures[f"{kind}_p99_ratio"] = round(p99_ratio, 3)
        figures[f"{kind}_throughput_ratio"] = round(thr_ratio, 3)
        print(
            f"{kind:8s} {row['raw']['bytes']:>7d} B | latency median raw "
            f"{row['raw']['latency_median_us']:8.1f} us, ours "
            f"{row['typed']['latency_median_us']:8.1f} us (x{lat_ratio:.2f}); p99 raw "
            f"{row['raw']['latency_p99_us']:8.1f} us, ours "
            f"{row['typed']['latency_p99_us']:8.1f} us (x{p99_ratio:.2f}) | throughput raw "
            f"{row['raw']['throughput_msgs_per_s']:9.0f}/s, ours "
            f"{row['typed']['throughput_msgs_per_s']:9.0f}/s (x{thr_ratio:.2f})",
            flush=True,
        )
    replay_figures = replay_speed()
    figures.update({k: round(v, 3) for k, v in replay_figures.items()})
    print(
        f"replay as fast as possible: skeleton only "
        f"{replay_figures['replay_skeleton_speed_x_realtime']:.0f}x real time, skeleton + "
        f"320x240 camera {replay_figures['replay_all_speed_x_realtime']:.0f}x real time",
        flush=True,
    )
    print(json.dumps(figures))
    return 0


if __name__ == "__main__":
    sys.exit(main())
