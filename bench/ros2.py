"""ROS 2: what the bridge costs per message next to a raw Zenoh hop, and rosbag2 export and
import next to rosbags reading the same bag alone, in one run.

1. Per message (skeleton frame, camera frame, description of recordings/three-actions.mcap):
   reference = our wire payload put on one Zenoh session and received by another on loopback;
   ours = the bridge's path for it (services.ros2_bridge: decode, convert to CDR, put with
   rmw_zenoh's attachment; a description also written to the said log first) to a
   subscriber on the ROS 2 data key. CPU per message, and a core's share at 30 Hz skeleton +
   15 fps camera (goal <= 10 %).
2. Latency a description gains: p50/p99 of one description at a time through the bridge next to
   the raw hop, idle and with three busy loops (goal: <= 1 ms p99 added).
3. DDS (bench/ros2_dds.py): the bridge's DDS path next to real rclpy on Fast DDS publishing the
   same messages (the anchor, Kilted's PyPI wheels in tests' side environment), both to a real
   rclpy subscriber: CPU per message and a core's share at 30 Hz + 15 fps beside the anchor's
   and rmw_zenoh's; description latency p99 added over rclpy's own (goal <= 1 ms, idle).
4. rosbag2: export (runtime.ros2.bag.export) and import (read_recording of the bag: CDR to our
   messages) in messages/s and MB/s, next to rosbags' Reader + deserialize_cdr on the same bag.
Last line: one JSON object with every figure.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import statistics
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import zenoh

from beyond_self.cognition.paths import DEMO_RECORDING
from beyond_self.runtime.recording.reader import read_recording
from beyond_self.runtime.resilience.effect_log import EffectLog
from beyond_self.runtime.ros2.bag_export import export
from beyond_self.runtime.ros2.convert import store, to_ros
from beyond_self.runtime.ros2.node import Ros2Node
from beyond_self.schemas import ros2 as r
from beyond_self.schemas.base import Header, Message
from beyond_self.schemas.codec import decode, encode
from beyond_self.schemas.messages import Description, Evidence, ScoredSentence

RECORDING = Path(DEMO_RECORDING).with_name("three-actions.mcap")
ROUNDS = 300


def session(port: int, mode: str = "peer") -> zenoh.Session:
    """A router listening on `port` (mode "router"), or a peer of it, on loopback."""
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps(mode))
    side = "listen" if mode == "router" else "connect"
    config.insert_json5(f"{side}/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    config.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(config)


class Counter:
    """A subscriber's arrivals: a count and the time of the last, woken per arrival."""

    def __init__(self) -> None:
        self.count = 0
        self.event = threading.Event()

    def __call__(self, _sample: Any) -> None:
        self.count += 1
        self.event.set()

    def wait_for(self, n: int) -> None:
        deadline = time.monotonic() + 30
        while self.count < n and time.monotonic() < deadline:
            self.event.wait(0.5)
            self.event.clear()
        assert self.count >= n, f"{self.count} of {n} arrived"


def samples() -> dict[str, list[tuple[type[Message], bytes]]]:
    """Wire payloads of one kind each: skeleton and camera frames, and descriptions."""
    out: dict[str, list[tuple[type[Message], bytes]]] = {"skeleton": [], "camera": []}
    for item in read_recording(RECORDING):
        kind = "skeleton" if item.key.endswith("skeleton") else "camera"
        out[kind].append((item.cls, encode(item.message())))  # type: ignore[arg-type]
    sentence = "the robot grasped the ball and the ball is rising"
    out["description"] = [
        (Description, encode(Description(
            header=Header(version=1, source="bench", seq=i, stamp=10**18 + i), segment_id=i,
            sentences=[ScoredSentence(text=sentence, score=-1.0)], evidence=Evidence(),
        )))
        for i in range(1, ROUNDS + 1)
    ]  # fmt: skip
    return out


def per_message(
    port: int, kind: str, items: list[tuple[type[Message], bytes]], log: Path
) -> dict[str, float]:
    """CPU-s per message: raw hop and the bridge's path, each over the same payloads."""
    items = (items * (ROUNDS // len(items) + 1))[:ROUNDS]
    a, b = session(port), session(port)
    stream = {"skeleton": "skeleton", "camera": "camera_compressed"}.get(kind, "description")
    node = Ros2Node("bench", "/bench", connect=f"tcp/127.0.0.1:{port}", domain=0)
    try:
        raw = Counter()
        sub = b.declare_subscriber(f"bench/{kind}", raw)
        pub = a.declare_publisher(f"bench/{kind}", congestion_control=zenoh.CongestionControl.BLOCK)
        ros = Counter()
        topic, ros_type = f"/bench/{kind}", r.TOPICS[stream][1]
        out = node.publisher(topic, ros_type, r.RELIABLE_QOS)  # blocks, as the raw hop
        ros_sub = b.declare_subscriber(
            r.data_key(0, topic, ros_type, store().hash_rihs01(ros_type)), ros
        )
        time.sleep(0.5)  # routes
        said = EffectLog(log, sync=False)

        def raw_hop() -> None:
            for _, payload in items:
                pub.put(payload)
            raw.wait_for(len(items))

        def bridge() -> None:
            for cls, payload in items:
                message = decode(payload, cls)
                converted = to_ros(stream, message)
                assert converted is not None
                if isinstance(message, Description):
                    said.append(message.header.stamp, message.segment_id, "-", "x")
                out.put(converted[1], message.header.stamp)
            ros.wait_for(len(items))

        reference = timed(raw_hop) / len(items)
        ours = timed(bridge) / len(items)
        sub.undeclare()
        ros_sub.undeclare()
    finally:
        node.close()
        a.close()  # type: ignore[no-untyped-call]
        b.close()  # type: ignore[no-untyped-call]
    return {"raw_s": reference, "bridge_s": ours, "ratio": ours / reference}


def timed(fn: Callable[[], None]) -> float:
    start = time.process_time()
    fn()
    return time.process_time() - start


def latency(port: int, log: Path) -> dict[str, float]:
    """p50/p99 seconds of one description at a time: raw hop and through the bridge."""
    a, b = session(port), session(port)
    node = Ros2Node("bench_latency", "/bench", connect=f"tcp/127.0.0.1:{port}", domain=0)
    arrived = threading.Event()
    try:
        b.declare_subscriber("bench/latency", lambda _s: arrived.set())
        pub = a.declare_publisher("bench/latency")
        out = node.publisher("/bench/said", r.STRING, r.RELIABLE_QOS)
        key = r.data_key(0, "/bench/said", r.STRING, store().hash_rihs01(r.STRING))
        b.declare_subscriber(key, lambda _s: arrived.set())
        time.sleep(0.5)
        said = EffectLog(log, sync=False)
        payload = samples_description()

        def raw() -> None:
            pub.put(payload)

        def bridge() -> None:
            message = decode(payload, Description)
            converted = to_ros("description", message)
            assert converted is not None
            said.append(message.header.stamp, message.segment_id, "-", "x")
            out.put(converted[1], message.header.stamp)

        times: dict[str, list[float]] = {"raw": [], "bridge": []}
        for i in range(ROUNDS + 20):  # alternated, so both meet the same machine; 20 warm-up
            for name, send in (("raw", raw), ("bridge", bridge)):
                arrived.clear()
                start = time.perf_counter()
                send()
                assert arrived.wait(5)
                if i >= 20:
                    times[name].append(time.perf_counter() - start)
        figures: dict[str, float] = {}
        for name, got in times.items():
            got.sort()
            figures[f"{name}_p50_s"] = statistics.median(got)
            figures[f"{name}_p99_s"] = got[int(0.99 * len(got)) - 1]
        figures["added_p99_s"] = figures["bridge_p99_s"] - figures["raw_p99_s"]
        return figures
    finally:
        node.close()
        a.close()  # type: ignore[no-untyped-call]
        b.close()  # type: ignore[no-untyped-call]


def samples_description() -> bytes:
    return encode(Description(
        header=Header(version=1, source="bench", seq=1, stamp=10**18), segment_id=1,
        sentences=[ScoredSentence(text="the robot tapped the blue cube", score=-1.0)],
        evidence=Evidence(),
    ))  # fmt: skip


def _spin() -> None:
    while True:
        pass


@contextmanager
def busy_loops(n: int) -> Iterator[None]:
    procs = [multiprocessing.Process(target=_spin, daemon=True) for _ in range(n)]
    for p in procs:
        p.start()
    try:
        yield
    finally:
        for p in procs:
            p.terminate()
            p.join()


def bags(work: Path) -> dict[str, float]:
    """Export and import throughput of a rosbag2 bag, and rosbags reading it alone."""
    from rosbags.rosbag2 import Reader

    bag = work / "bag"
    start = time.perf_counter()
    exported = export(RECORDING, bag).messages
    export_s = time.perf_counter() - start
    size = sum(f.stat().st_size for f in bag.iterdir())
    start = time.perf_counter()
    imported = sum(1 for item in read_recording(bag) if item.message() is not None)
    import_s = time.perf_counter() - start
    start = time.perf_counter()
    with Reader(bag) as reader:
        alone = sum(1 for c, _, raw in reader.messages() if store().deserialize_cdr(raw, c.msgtype))
    rosbags_s = time.perf_counter() - start
    assert exported == imported == alone
    mb = size / 1e6
    return {
        "messages": exported,
        "bag_mb": mb,
        "export_msgs_per_s": exported / export_s,
        "export_mb_per_s": mb / export_s,
        "import_msgs_per_s": imported / import_s,
        "import_mb_per_s": mb / import_s,
        "rosbags_msgs_per_s": alone / rosbags_s,
        "rosbags_mb_per_s": mb / rosbags_s,
        "import_vs_rosbags": rosbags_s / import_s,
    }


def main() -> None:
    # no options: --help says what it measures and exits
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.parse_args()
    from socket import socket

    with socket() as s:
        s.bind(("127.0.0.1", 0))
        port = int(s.getsockname()[1])
    hub = session(port, "router")
    results: dict[str, Any] = {}
    try:
        with tempfile.TemporaryDirectory() as tmp:
            work = Path(tmp)
            for kind, items in samples().items():
                figures = per_message(port, kind, items, work / f"{kind}.log")
                results[kind] = figures
                raw_us, ours_us = figures["raw_s"] * 1e6, figures["bridge_s"] * 1e6
                print(f"{kind:12s} raw hop {raw_us:8.1f} us  bridge {ours_us:8.1f} us "
                      f"CPU/message  ratio {figures['ratio']:.2f}")  # fmt: skip
            share = 30 * results["skeleton"]["bridge_s"] + 15 * results["camera"]["bridge_s"]
            results["core_share_30hz_15fps"] = share
            print(f"bridge at 30 Hz skeleton + 15 fps camera: {share:.1%} of a core (goal <= 10%)")
            for label, busy in (("idle", 0), ("busy3", 3)):
                with busy_loops(busy):
                    figures = latency(port, work / f"latency-{label}.log")
                results[f"latency_{label}"] = figures
                raw_ms, ours_ms = figures["raw_p99_s"] * 1e3, figures["bridge_p99_s"] * 1e3
                added = figures["added_p99_s"] * 1e3
                print(f"description latency ({label}): raw p99 {raw_ms:.2f} ms, bridge p99 "
                      f"{ours_ms:.2f} ms, added {added:.2f} ms (goal <= 1 ms)")  # fmt: skip
            from ros2_dds import figures

            dds = results["dds"] = figures(work, samples(), ROUNDS)
            shares = {
                name: 30 * dds["skeleton"][key] + 15 * dds["camera"][key]
                for name, key in (("dds_bridge", "dds_bridge_s"), ("rclpy", "rclpy_s"))
            }
            shares["zenoh_bridge"] = share
            dds["core_share_30hz_15fps"] = shares
            for kind in ("skeleton", "camera", "description"):
                f = dds[kind]
                anchor_us, ours_us = f["rclpy_s"] * 1e6, f["dds_bridge_s"] * 1e6
                print(f"{kind:12s} rclpy (Fast DDS) {anchor_us:8.1f} us  DDS bridge "
                      f"{ours_us:8.1f} us CPU/message  ratio {f['ratio']:.2f}")  # fmt: skip
            print(f"at 30 Hz skeleton + 15 fps camera: DDS bridge {shares['dds_bridge']:.1%}, "
                  f"rclpy {shares['rclpy']:.1%}, rmw_zenoh bridge {shares['zenoh_bridge']:.1%} "
                  f"of a core (goal <= 10%); DDS/rclpy "
                  f"{shares['dds_bridge'] / shares['rclpy']:.2f}, DDS/zenoh "
                  f"{shares['dds_bridge'] / shares['zenoh_bridge']:.2f}")  # fmt: skip
            print(f"description latency over DDS (idle): rclpy p99 "
                  f"{dds['latency_rclpy_p99_s'] * 1e3:.2f} ms, DDS bridge p99 "
                  f"{dds['latency_dds_bridge_p99_s'] * 1e3:.2f} ms, added "
                  f"{dds['latency_added_p99_s'] * 1e3:.2f} ms (goal <= 1 ms)")  # fmt: skip
            results["bag"] = b = bags(work)
            print(f"rosbag2 ({b['messages']} messages, {b['bag_mb']:.1f} MB): export "
                  f"{b['export_msgs_per_s']:.0f} msg/s {b['export_mb_per_s']:.1f} MB/s; import "
                  f"{b['import_msgs_per_s']:.0f} msg/s {b['import_mb_per_s']:.1f} MB/s; rosbags "
                  f"alone {b['rosbags_msgs_per_s']:.0f} msg/s {b['rosbags_mb_per_s']:.1f} MB/s; "
                  f"import/rosbags speed {b['import_vs_rosbags']:.2f}")  # fmt: skip
    finally:
        hub.close()  # type: ignore[no-untyped-call]
    print(json.dumps(results))


if __name__ == "__main__":
    main()
