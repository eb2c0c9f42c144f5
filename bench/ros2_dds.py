"""bench/ros2.py's DDS part: the bridge's DDS path (runtime.ros2.dds, Cyclone DDS) next to real
rclpy on Fast DDS publishing the same messages (the anchor), both to one real rclpy
subscriber, on loopback in a DDS domain of their own. CPU per message in the publishing
process, and the wall time from a description to its arrival in the subscriber."""

from __future__ import annotations

import base64
import json
import os
import queue
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from beyond_self.runtime.resilience.effect_log import EffectLog
from beyond_self.runtime.ros2.convert import to_ros
from beyond_self.runtime.ros2.dds import DdsNode
from beyond_self.runtime.ros2.rmw import cyclone_config
from beyond_self.schemas import ros2 as r
from beyond_self.schemas.base import Message
from beyond_self.schemas.codec import decode
from beyond_self.schemas.messages import Description

NODES = Path(__file__).resolve().parent / "rclpy_nodes"
STREAMS = {"skeleton": "skeleton", "camera": "camera_compressed", "description": "description"}
TOPICS = {"skeleton": "/bench/skeleton", "camera": "/bench/camera", "description": "/bench/said"}


class Lines:
    """A child's JSON lines, read by a thread."""

    def __init__(self, process: subprocess.Popen[str]) -> None:
        self.process = process
        self.queue: queue.Queue[dict[str, Any]] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.queue.put(json.loads(line))

    def next(self, timeout: float = 30) -> dict[str, Any]:
        return self.queue.get(timeout=timeout)

    def say(self, text: str) -> None:
        assert self.process.stdin is not None
        self.process.stdin.write(text + "\n")
        self.process.stdin.flush()


def side_environment() -> Path:
    """The real rclpy side environment the tests use (tests/rclpyutil.py)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
    from rclpyutil import side_python  # type: ignore[import-not-found]

    found: Path = side_python()
    return found


def figures(
    work: Path, items: dict[str, list[tuple[type[Message], bytes]]], rounds: int
) -> dict[str, Any]:
    python = side_environment()
    from rclpyutil import loopback_env, private_domain  # type: ignore[import-not-found]

    env = {**os.environ, **loopback_env(work, private_domain())}
    os.environ.update(env)  # our participant reads the same domain and discovery settings
    records = work / "records.jsonl"
    with records.open("w") as f:
        for kind, payloads in items.items():
            for cls, payload in payloads[:rounds]:
                ros_type, cdr = to_ros(STREAMS[kind], decode(payload, cls)) or ("", b"")
                line = {"kind": kind, "type": ros_type, "cdr": base64.b64encode(cdr).decode()}
                f.write(json.dumps(line) + "\n")
    counter = Lines(subprocess.Popen(
        [str(python), str(NODES / "counter.py")], env=env, stdin=subprocess.PIPE,
        stdout=subprocess.PIPE, text=True,
    ))  # fmt: skip
    anchor = Lines(subprocess.Popen(
        [str(python), str(NODES / "publisher.py"), str(records)], env=env,
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
    ))  # fmt: skip
    node = DdsNode("bench", "/bench", domain=int(env["ROS_DOMAIN_ID"]), config=cyclone_config())
    try:
        assert counter.next(60) == {"ready": True}
        out = {
            kind: node.publisher(
                TOPICS[kind], r.TOPICS[STREAMS[kind]][1],
                r.RELIABLE_QOS if kind == "description" else r.SENSOR_QOS,
            )
            for kind in items
        }  # fmt: skip
        while not all(p.writer.get_matched_subscriptions() for p in out.values()):
            time.sleep(0.05)
        assert anchor.next(60) == {"ready": True}
        said = EffectLog(work / "dds-said.log", sync=False)

        def bridge(cls: type[Message], payload: bytes, kind: str) -> None:
            message = decode(payload, cls)
            converted = to_ros(STREAMS[kind], message)
            assert converted is not None
            if isinstance(message, Description):
                said.append(message.header.stamp, message.segment_id, "-", "x")
            out[kind].put(converted[1], message.header.stamp)

        result: dict[str, Any] = {}
        for kind, payloads in items.items():
            batch = (payloads * (rounds // len(payloads) + 1))[:rounds]
            start = time.process_time()
            for cls, payload in batch:
                bridge(cls, payload, kind)
            ours = (time.process_time() - start) / rounds
            anchor.say(f"cpu {kind} {rounds}")
            rclpy_s = anchor.next()["cpu_s"] / rounds
            result[kind] = {"dds_bridge_s": ours, "rclpy_s": rclpy_s, "ratio": ours / rclpy_s}
        for _ in range(3):  # the last reliable samples arrive before latency is timed
            while not counter.queue.empty():
                counter.next()
            time.sleep(0.2)
        cls, payload = items["description"][0]
        times: dict[str, list[float]] = {"rclpy": [], "dds_bridge": []}
        for i in range(rounds + 20):  # alternated; 20 warm-up
            anchor.say("one")
            started = anchor.next()["started"]
            arrived = counter.next()["said"]
            begun = time.time_ns()
            bridge(cls, payload, "description")
            ours_arrived = counter.next()["said"]
            if i >= 20:
                times["rclpy"].append((arrived - started) / 1e9)
                times["dds_bridge"].append((ours_arrived - begun) / 1e9)
        for name, got in times.items():
            got.sort()
            result[f"latency_{name}_p50_s"] = statistics.median(got)
            result[f"latency_{name}_p99_s"] = got[int(0.99 * len(got)) - 1]
        result["latency_added_p99_s"] = (
            result["latency_dds_bridge_p99_s"] - result["latency_rclpy_p99_s"]
        )
        return result
    finally:
        node.close()
        for child in (anchor, counter):
            child.say("quit")
            child.process.wait(10)
