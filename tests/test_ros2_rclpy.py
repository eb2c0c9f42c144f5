"""The ROS 2 bridge over DDS, ROS 2's default middleware, judged by real rclpy on Fast DDS
(Kilted's wheels from PyPI, in a side environment: tests/rclpyutil.py): a listener hears each
of `beyond analyse`'s sentences once and sees the bridge's topics with their types; a real
rclpy publisher plays a recording into `beyond up` with the ROS 2 live source, which describes
it as `beyond analyse` does. Every DDS packet stays on loopback, in a domain of the test's own."""

from __future__ import annotations

import asyncio
import base64
import json
import queue
import signal
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import pytest
from busutil_net import env_for, private_config, run_beyond
from rclpyutil import NODES, loopback_env, private_domain, side_python
from ros2util import STORE, ProgressWatch
from test_ros2_bridge import TOUCH, frameless, jpeg_image, k4abt_markers

from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.recording.reader import read_recording
from beyond_self.schemas import ros2 as r
from beyond_self.schemas.messages import CompressedCameraFrame, SkeletonFrame
from beyond_self.services.launcher import BEYOND

THREE = Path(__file__).resolve().parent.parent / "recordings" / "three-actions.mcap"


class Judge:
    """The rclpy node's JSON lines, read by a thread and taken with a deadline."""

    def __init__(self, process: subprocess.Popen[str]) -> None:
        self.process = process
        self.heard: list[str] = []
        self.lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for text in self.process.stdout:
            self.lines.put(text)

    def line(self, timeout: float) -> dict[str, Any] | None:
        try:
            text = self.lines.get(timeout=max(timeout, 0.0))
        except queue.Empty:
            return None
        found: dict[str, Any] = json.loads(text)
        if "data" in found:
            self.heard.append(found["data"])
        return found

    def until(self, key: str, timeout: float) -> dict[str, Any]:
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            found = self.line(left)
            if found is not None and key in found:
                return found
        raise AssertionError(f"the rclpy node said no {key!r} in {timeout} s")

    def ask(self, question: str) -> None:
        assert self.process.stdin is not None
        self.process.stdin.write(question + "\n")
        self.process.stdin.flush()


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_real_rclpy_hears_each_sentence_once_over_dds(tmp_path: Path, test_outputs: Path) -> None:
    python = side_python()
    config = private_config()
    ros = loopback_env(tmp_path, private_domain())
    env = env_for(config, **ros)
    analysed = subprocess.run(
        [*BEYOND, "analyse", str(THREE)], env=env, cwd=tmp_path, capture_output=True, text=True,
        timeout=120,
    )  # fmt: skip
    assert analysed.returncode == 0, analysed.stderr[-2000:]
    sentences = [line.split(": ", 1)[1].strip('"') for line in analysed.stdout.splitlines()
                 if ': "' in line]  # fmt: skip
    assert len(sentences) == 3, analysed.stdout
    topic = f"/{config.robot}/description"
    judge = Judge(subprocess.Popen(
        [str(python), str(NODES / "listener.py"), topic, f"/{config.robot}/body_tracking_data"],
        env=env, cwd=tmp_path,
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
    ))  # fmt: skip
    try:
        judge.until("ready", 60)
        up = subprocess.Popen(
            [*BEYOND, "up", "--recording", str(THREE), "--ros2", "--no-live", "--rate", "1",
             "--timeout", "90"],
            env=env, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        try:
            judge.until("data", 90)
            ns = f"/{config.robot}"
            wanted = {
                f"{ns}/description": [r.STRING],
                f"{ns}/body_tracking_data": [r.MARKER_ARRAY],
                f"{ns}/camera/image/compressed": [r.COMPRESSED_IMAGE],
                f"{ns}/person/image/compressed": [r.COMPRESSED_IMAGE],
            }
            ours = [f"beyond_{config.robot}", ns]
            for _ in range(20):  # discovery goes on in the background: asked until complete
                judge.ask("graph")
                graph = judge.until("nodes", 10)
                topics = {name: types for name, types in graph["topics"]}
                if ours in graph["nodes"] and all(topics.get(t) == v for t, v in wanted.items()):
                    break
                time.sleep(0.2)
            assert {t: topics.get(t) for t in wanted} == wanted, graph
            assert ours in graph["nodes"], graph  # get_node_names_and_namespaces()
            out, err = up.communicate(timeout=150)
        finally:
            if up.poll() is None:
                up.kill()
                up.communicate()
        assert up.returncode == 0, err[-3000:]
        deadline = time.monotonic() + 20  # what is still on its way
        while len(judge.heard) < len(sentences) and judge.line(deadline - time.monotonic()):
            pass
        judge.ask("graph")
        assert judge.until("nodes", 10)["markers"] > 0  # the skeleton, as MarkerArrays
    finally:
        judge.ask("quit")
        judge.process.wait(10)
    said_by_up = [line.split(": ", 1)[1].strip('"') for line in out.splitlines() if ': "' in line]
    assert said_by_up == sentences
    said = (test_outputs / "ros2" / "said.log").read_text().splitlines()
    assert [line.split("\t")[3] for line in said] == sentences  # each published once
    assert judge.heard == sentences  # what rclpy heard: each once, in order


def records(path: Path, robot: str) -> list[str]:
    """touch-box.mcap as a ROS 2 body tracker and camera publish it (the Azure Kinect driver's
    markers: K4ABT ids, its frame `depth_camera_link` and axes; a JPEG CompressedImage), in CDR
    rosbags serializes, one JSON line each for the rclpy player; the recording's kinds in order."""
    ns = f"/{robot}"
    keys: list[str] = []
    with path.open("w") as f:
        for item in read_recording(TOUCH):
            message = item.message()
            if isinstance(message, SkeletonFrame):
                topic, ros_type = f"{ns}/body_tracking_data", r.MARKER_ARRAY
                fields = k4abt_markers(STORE.types, message)
                keys.append("skeleton")
            else:
                assert isinstance(message, CompressedCameraFrame)
                topic, ros_type = f"{ns}/camera/image/compressed", r.COMPRESSED_IMAGE
                fields = jpeg_image(STORE.types, message)
                keys.append("camera")
            cdr = bytes(STORE.serialize_cdr(STORE.types[ros_type](**fields), ros_type))
            line = {"topic": topic, "type": ros_type, "cdr": base64.b64encode(cdr).decode()}
            f.write(json.dumps(line) + "\n")
    return keys


@pytest.mark.slow
@pytest.mark.timeout(240)
async def test_a_real_rclpy_body_tracker_and_camera_are_described_as_analyse_does(
    tmp_path: Path,
) -> None:
    """Real rclpy publishes touch-box.mcap as a body tracker and a camera over Fast DDS into
    `beyond up --live-source ros2_source` (DDS, the default): `up` prints `analyse`'s lines.
    As in the rmw_zenoh test, each message goes out once every consumer of its stream has
    handled the one before (their Progress): a live source is never held back, so this keeps
    the run independent of timing."""
    python = side_python()
    config = private_config()
    ros = loopback_env(tmp_path, private_domain())
    code, out, err = await run_beyond(
        ["analyse", str(TOUCH)], env=env_for(config), cwd=tmp_path, timeout=60
    )
    assert code == 0, err[-3000:]
    expected = frameless(out.splitlines())
    assert any(': "' in line for line in expected), expected
    kinds = records(tmp_path / "records.jsonl", config.robot)
    ns = f"/{config.robot}"
    env = env_for(
        config, **ros, BEYOND_ROS2_SKELETON=f"{ns}/body_tracking_data",
        BEYOND_ROS2_CAMERA=f"{ns}/camera/image/compressed", BEYOND_ROS2_TF="",
        BEYOND_ROS2_CAMERA_RAW="",
    )  # fmt: skip
    bus = Bus.open(config)
    keys = bus.keys
    watch = ProgressWatch(bus)
    handled, until = watch.handled, watch.until

    loop = asyncio.get_running_loop()
    watching = loop.create_task(watch.run())
    lines: list[str] = []
    said = asyncio.Event()
    up = await asyncio.create_subprocess_exec(
        *BEYOND, "up", "--live-source", "beyond_self.services.ros2_source:source",
        "--without", "speech", "--no-live", "--timeout", "60",
        env=env, cwd=tmp_path, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    player = await asyncio.create_subprocess_exec(
        str(python), str(NODES / "player.py"), str(tmp_path / "records.jsonl"),
        env=env, cwd=tmp_path, stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE,
    )  # fmt: skip
    assert up.stdout is not None and up.stderr is not None
    assert player.stdin is not None and player.stdout is not None

    async def read_lines() -> None:
        assert up.stdout is not None
        async for raw in up.stdout:
            lines.append(raw.decode().rstrip("\n"))
            if ': "' in lines[-1]:
                said.set()

    matched: set[str] = set()
    both_matched = asyncio.Event()
    stderr_lines: list[str] = []

    async def read_errors() -> None:  # the live source says when it matched each publisher
        assert up.stderr is not None
        async for raw in up.stderr:
            stderr_lines.append(raw.decode())
            if "ROS 2 publishers matched" in stderr_lines[-1]:
                found = json.loads(stderr_lines[-1].split("] ", 1)[1])
                if found.get("publishers", 0) > 0:
                    matched.add(found["topic"])
                    if len(matched) == 2:
                        both_matched.set()

    reading = loop.create_task(read_lines())
    errors = loop.create_task(read_errors())
    try:
        answer = await asyncio.wait_for(player.stdout.readline(), 60)
        assert json.loads(answer) == {"matched": True}  # rclpy sees both subscriptions
        try:
            await asyncio.wait_for(both_matched.wait(), 30)  # and they see both its publishers
        except TimeoutError:
            raise AssertionError("".join(stderr_lines)[-3000:]) from None
        stream_keys = {"skeleton": keys.skeleton, "camera": keys.camera}
        await until(
            lambda: all(any(k in s for s in handled.values()) for k in stream_keys.values()),
            "the consumers",
        )
        consumers = {
            k: {name for name, stamps in handled.items() if k in stamps}
            for k in stream_keys.values()
        }
        stamps = [item.message().header.stamp for item in read_recording(TOUCH)]
        for index, kind in enumerate(kinds):
            key = stream_keys[kind]
            player.stdin.write(f"{index}\n".encode())
            await player.stdin.drain()
            sent = json.loads(await asyncio.wait_for(player.stdout.readline(), 10))
            assert sent == {"sent": index}
            stamp = stamps[index]
            await until(
                lambda key=key, stamp=stamp: all(
                    handled[name][key] >= stamp for name in consumers[key]
                ),
                f"{key} at {stamp}",
            )
        try:
            await asyncio.wait_for(said.wait(), 20)
        except TimeoutError:
            raise AssertionError(f"no sentence 20 s after the last frame: {lines}") from None
        up.send_signal(signal.SIGINT)
        await asyncio.wait_for(up.wait(), 30)
        await reading
    finally:
        for process in (up, player):
            if process.returncode is None:
                process.kill()
                await process.wait()
        watching.cancel()
        bus.close()
    await errors
    stderr = "".join(stderr_lines)
    assert up.returncode == 0, stderr[-3000:]
    assert frameless(lines) == expected, stderr[-3000:]
