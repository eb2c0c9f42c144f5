"""The ROS 2 bridge, judged by an independent implementation of rmw_zenoh's protocol
(zenoh-ros2-sdk on PyPI: its own key expressions, type hashes, attachment parsing and rosbags
decoding) through a plain Zenoh router: `beyond up --ros2` says each sentence of a recording
once on /<robot>/description, also when the bridge is SIGKILLed in the middle; and a recording
its publisher plays as a ROS 2 body tracker and camera into `beyond up --live-source` is
described as `beyond analyse` describes the recording."""

from __future__ import annotations

import asyncio
import io
import os
import re
import signal
import subprocess
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import zenoh
from busutil_net import env_for, free_port, private_config, run_beyond
from ros2util import STORE, ProgressWatch, plain_router, zero
from zenoh_ros2_sdk.attachment import Attachment

from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.recording.reader import read_recording
from beyond_self.runtime.ros2.node import attachment, read_attachment
from beyond_self.schemas import ros2 as r
from beyond_self.schemas.messages import CompressedCameraFrame, SkeletonFrame
from beyond_self.services.launcher import BEYOND

THREE = Path(__file__).resolve().parent.parent / "recordings" / "three-actions.mcap"


def test_attachment_is_the_design_documents_layout() -> None:
    """8 bytes sequence number, 8 bytes source timestamp (little-endian int64), 1 byte GID
    length (16), 16 bytes GID; read back by zenoh-ros2-sdk's own parser."""
    gid = bytes(range(1, 17))
    data = attachment(7, 1_546_300_800_123_456_789, gid)
    assert len(data) == 33
    assert data[:8] == (7).to_bytes(8, "little")
    assert data[8:16] == (1_546_300_800_123_456_789).to_bytes(8, "little")
    assert data[16] == 16 and data[17:] == gid
    theirs = Attachment.from_bytes(data)
    assert (theirs.sequence_id, theirs.timestamp_ns, theirs.gid) == (
        7,
        1_546_300_800_123_456_789,
        gid,
    )
    assert read_attachment(data) == (7, 1_546_300_800_123_456_789, gid)


def child_running(parent: int, word: str) -> int | None:
    """The pid of a child of `parent` whose command line holds `word`."""
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            cmdline = (entry / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if int(stat.rsplit(")", 1)[1].split()[1]) == parent and word.encode() in cmdline:
            return int(entry.name)
    return None


@pytest.mark.slow
def test_a_ros2_subscriber_hears_each_sentence_once_across_a_killed_bridge(
    tmp_path: Path, test_outputs: Path
) -> None:
    from zenoh_ros2_sdk import ROS2Subscriber
    from zenoh_ros2_sdk.discovery import get_topic_names_and_types
    from zenoh_ros2_sdk.session import ZenohSession

    port = free_port()
    config = private_config()
    topic = f"/{config.robot}/description"
    heard: list[str] = []
    first = threading.Event()

    def on_string(message: object) -> None:
        heard.append(str(message.data))  # type: ignore[attr-defined]
        first.set()

    with plain_router(port) as router:
        # everything the bridge publishes, as any Zenoh session on the graph receives it
        samples: list[tuple[str, bytes, bytes]] = []
        router.declare_subscriber(
            f"0/{config.robot}/**",
            lambda s: samples.append(
                (
                    str(s.key_expr),
                    s.payload.to_bytes(),
                    s.attachment.to_bytes() if s.attachment else b"",
                )
            ),
        )
        subscriber = ROS2Subscriber(
            topic=topic,
            msg_type=r.STRING,
            callback=on_string,
            msg_definition="string data",
            router_ip="127.0.0.1",
            router_port=port,
        )
        up = subprocess.Popen(
            [*BEYOND, "up", "--recording", str(THREE), "--ros2", "--ros2-rmw", "zenoh",
             "--ros2-connect", f"tcp/127.0.0.1:{port}", "--no-live", "--rate", "1",
             "--timeout", "60"],
            env=env_for(config), cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        try:
            assert first.wait(90), "no sentence reached the ROS 2 subscriber"
            # the graph as `ros2 node list` / `ros2 topic list -t` read it: liveliness tokens
            tokens = [str(reply.ok.key_expr) for reply in router.liveliness().get("@ros2_lv/0/**")
                      if reply.ok is not None]  # fmt: skip
            string_hash = STORE.hash_rihs01(r.STRING)
            node = f"NN/%/%{config.robot}/beyond_{config.robot}"
            publisher = (f"MP/%/%{config.robot}/beyond_{config.robot}/%{config.robot}%description/"
                         f"std_msgs::msg::dds_::String_/{string_hash}/::,10:,:,:,,")  # fmt: skip
            assert any(t.endswith(node) for t in tokens), tokens
            assert any(t.endswith(publisher) for t in tokens), tokens
            # and as zenoh-ros2-sdk's `ros2 topic list -t` reads them
            ns = f"/{config.robot}"
            wanted = (
                f"{ns}/description",
                f"{ns}/body_tracking_data",
                f"{ns}/camera/image/compressed",
                f"{ns}/person/image/compressed",
            )
            # its listing gathers tokens for `timeout` s: on a busy machine one round can miss
            # some, so it is asked again (at most 10 rounds) until every topic is listed
            for _ in range(10):
                listed = dict(get_topic_names_and_types(0, "127.0.0.1", port, timeout=1.0))
                if all(t in listed for t in wanted):
                    break
            assert {t: listed.get(t) for t in (f"{ns}/description", f"{ns}/body_tracking_data",
                    f"{ns}/camera/image/compressed", f"{ns}/person/image/compressed")} == {
                f"{ns}/description": [r.STRING],
                f"{ns}/body_tracking_data": [r.MARKER_ARRAY],
                f"{ns}/camera/image/compressed": [r.COMPRESSED_IMAGE],
                f"{ns}/person/image/compressed": [r.COMPRESSED_IMAGE],
            }  # fmt: skip
            bridge = child_running(up.pid, "ros2")
            assert bridge is not None
            os.kill(bridge, signal.SIGKILL)
            out, err = up.communicate(timeout=120)
        finally:
            if up.poll() is None:
                up.kill()
                up.communicate()
            subscriber.close()
            ZenohSession.get_instance().close()
    assert up.returncode == 0, err[-3000:]
    assert "[up] ros2:" in err  # it died and was started again
    said_by_up = [line.split(": ", 1)[1].strip('"') for line in out.splitlines() if ': "' in line]
    assert heard == said_by_up  # each once, in order, as `up` printed them (analyse's lines)
    assert len(heard) == 3
    by_type: dict[str, int] = {}
    stamps = {item.publish_time for item in read_recording(THREE)}
    for key, payload, extra in samples:  # rosbags decodes each, the key's hash is rosbags'
        dds, type_hash = key.split("/")[-2:]
        package, kind, name = dds.split("::")[0], dds.split("::")[1], dds.split("::")[3]
        ros_type = f"{package}/{kind}/{name.rstrip('_')}"
        assert type_hash == STORE.hash_rihs01(ros_type), key
        message = STORE.deserialize_cdr(payload, ros_type)
        attached = Attachment.from_bytes(extra)  # zenoh-ros2-sdk's parser
        assert len(attached.gid) == 16
        if ros_type != r.STRING:  # a sensor frame: its own stamp, in header and attachment
            header = message.markers[0].header if ros_type == r.MARKER_ARRAY else message.header
            stamp = header.stamp.sec * 10**9 + header.stamp.nanosec
            assert stamp in stamps and attached.timestamp_ns == stamp
        by_type[ros_type] = by_type.get(ros_type, 0) + 1
    assert by_type[r.STRING] == 3
    assert by_type[r.MARKER_ARRAY] > 300 and by_type[r.COMPRESSED_IMAGE] > 150, by_type
    said = (test_outputs / "ros2" / "said.log").read_text().splitlines()  # runtime.outputs
    assert not (tmp_path / "out").exists()  # nothing in the current folder unasked
    assert [line.split("\t")[3] for line in said] == heard


async def test_ros2_body_markers_and_camera_are_a_live_source(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The ingest's ROS 2 plug-in reads what a plain Zenoh session publishes on rmw_zenoh's
    data keys in CDR rosbags serialized (no code of ours on that side): the Azure Kinect
    driver's markers (K4ABT ids, no names) become joints under our names, a CompressedImage
    an RGB image."""
    from PIL import Image

    from beyond_self.services.ros2_source import source

    port = free_port()
    robot = "rosbot"
    monkeypatch.setenv("BEYOND_ROBOT", robot)
    monkeypatch.setenv("BEYOND_ROS2_CONNECT", f"tcp/127.0.0.1:{port}")
    monkeypatch.setenv("ROS_DOMAIN_ID", "3")
    monkeypatch.setenv("RMW_IMPLEMENTATION", "rmw_zenoh_cpp")
    t = STORE.types
    stamp = t["builtin_interfaces/msg/Time"](sec=1, nanosec=5)
    header = t["std_msgs/msg/Header"](stamp=stamp, frame_id="depth_camera_link")
    marker = STORE.fielddefs["visualization_msgs/msg/Marker"][1]

    def one(k4abt: int, xyz: tuple[float, float, float]) -> object:
        fields = {n: zero(node) for n, node in marker}
        point = t["geometry_msgs/msg/Point"](*xyz)
        fields.update(header=header, id=k4abt, type=2)
        fields["pose"] = t["geometry_msgs/msg/Pose"](
            position=point, orientation=t["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0)
        )
        fields["color"] = t["std_msgs/msg/ColorRGBA"](1.0, 1.0, 1.0, 1.0)
        return t["visualization_msgs/msg/Marker"](**fields)

    markers = t[r.MARKER_ARRAY](markers=[one(15, (0.1, 0.2, 1.5)), one(1, (0.0, 0.0, 2.0))])
    jpeg = io.BytesIO()
    Image.fromarray(np.full((8, 12, 3), 200, np.uint8)).save(jpeg, "JPEG")
    image = t[r.COMPRESSED_IMAGE](
        header=header, format="jpeg", data=np.frombuffer(jpeg.getvalue(), np.uint8)
    )
    samples = [
        (f"3/{robot}/body_tracking_data", r.MARKER_ARRAY, markers),
        (f"3/{robot}/camera/image/compressed", r.COMPRESSED_IMAGE, image),
    ]
    with plain_router(port) as router:
        items = source()
        pending = asyncio.ensure_future(anext(items))
        got: list[tuple[str, object, int]] = []
        # the samples are put again until an item of each kind came: a put before the
        # plug-in's subscriptions have their routes is not delivered (no guess of how long
        # discovery takes; the test's timeout bounds it)
        while {kind for kind, _, _ in got} != {"skeleton", "camera"}:
            for key, ros_type, message in samples:
                typed = f"{key}/{r.dds_type(ros_type)}/{STORE.hash_rihs01(ros_type)}"
                router.put(typed, bytes(STORE.serialize_cdr(message, ros_type)))
            done, _ = await asyncio.wait({pending}, timeout=0.5)
            while done:
                got.append(pending.result())
                pending = asyncio.ensure_future(anext(items))
                done, _ = await asyncio.wait({pending}, timeout=0)
        pending.cancel()
        await asyncio.wait({pending})  # the generator is let go before it is closed
        await items.aclose()
    kinds = {kind: payload for kind, payload, _ in got}
    assert {stamp for _, _, stamp in got} == {1_000_000_005}  # the messages' own stamp
    # the driver's frame (x right, y down in the image) turned into ours (x to the person's
    # right, the image's left; y up): a half turn about z
    assert kinds["skeleton"] == {
        "right_hand": (-0.1, -0.2, 1.5, 1.0),
        "torso": (-0.0, -0.0, 2.0, 1.0),
    }
    camera = kinds["camera"]
    assert isinstance(camera, np.ndarray) and camera.shape == (8, 12, 3)


TOUCH = THREE.parent / "touch-box.mcap"  # the smallest shipped recording with a described touch


def frameless(lines: list[str]) -> list[str]:
    """Gesture lines without frame numbers: a recording numbers each stream's frames, a live
    source's ingest numbers its items across streams (ROS messages carry no frame index), so
    the same frame has another number; stamps, and so everything else, are the same."""
    return [re.sub(r"frame \d+", "frame N", line) for line in lines if line.startswith("gesture ")]


def k4abt_markers(types: dict[str, Any], frame: SkeletonFrame) -> dict[str, Any]:
    """The fields of a MarkerArray as the Azure Kinect ROS driver publishes a body: a sphere
    per joint, id body*100 + K4ABT joint id, metres, no joint name in `text`, in its frame
    `depth_camera_link`: x right and y down in the image (ours turned half about z)."""
    stamp = types["builtin_interfaces/msg/Time"](
        sec=frame.header.stamp // 10**9, nanosec=frame.header.stamp % 10**9
    )
    header = types["std_msgs/msg/Header"](stamp=stamp, frame_id="depth_camera_link")
    fields = {n: zero(node) for n, node in STORE.fielddefs["visualization_msgs/msg/Marker"][1]}
    markers = []
    for name, joint in frame.joints.items():
        k4abt = next(k for k, ours in r.OPENNI_OF_K4ABT.items() if ours == name)
        x, y, z = joint.position
        point = types["geometry_msgs/msg/Point"](-x, -y, z)
        upright = types["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0)
        fields.update(
            header=header,
            id=frame.user * 100 + r.K4ABT_JOINTS.index(k4abt),
            type=2,  # SPHERE
            pose=types["geometry_msgs/msg/Pose"](position=point, orientation=upright),
            color=types["std_msgs/msg/ColorRGBA"](0.0, 0.6, 1.0, joint.confidence),
        )
        markers.append(types["visualization_msgs/msg/Marker"](**fields))
    return {"markers": markers}


def jpeg_image(types: dict[str, Any], frame: CompressedCameraFrame) -> dict[str, Any]:
    """The fields of a sensor_msgs/CompressedImage of a recorded JPEG frame, its own stamp."""
    stamp = types["builtin_interfaces/msg/Time"](
        sec=frame.header.stamp // 10**9, nanosec=frame.header.stamp % 10**9
    )
    header = types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame.frame_id)
    return {"header": header, "format": frame.format, "data": np.frombuffer(frame.data, np.uint8)}


@pytest.mark.slow
@pytest.mark.timeout(120)
async def test_a_ros2_body_tracker_and_camera_are_described_as_analyse_does(
    tmp_path: Path,
) -> None:
    """zenoh-ros2-sdk's publisher (its own keys, attachment and CDR) plays touch-box.mcap as
    a ROS 2 body tracker (Azure Kinect markers) and a CompressedImage camera, through a plain
    Zenoh router, into `beyond up --live-source ros2_source`: `up` prints `analyse`'s lines.
    A live source is never held back (its queues drop their oldest), so the publisher is paced
    by the pipeline: each message goes out once every consumer of its stream has handled the
    one before (their Progress), which makes the run independent of timing: no queue ever
    holds more than one message, and every gesture sees every frame."""
    from zenoh_ros2_sdk import ROS2Publisher
    from zenoh_ros2_sdk.session import ZenohSession

    code, out, err = await run_beyond(
        ["analyse", str(TOUCH)], env=env_for(private_config()), cwd=tmp_path, timeout=60
    )
    assert code == 0, err[-3000:]
    expected = frameless(out.splitlines())
    assert any(': "' in line for line in expected), expected  # a described gesture

    port = free_port()
    config = private_config()
    ns = f"/{config.robot}"
    bus = Bus.open(config)
    keys = bus.keys
    watch = ProgressWatch(bus)
    handled, until = watch.handled, watch.until

    def consumers_of(key: str) -> set[str]:
        return {name for name, stamps in handled.items() if key in stamps}

    loop = asyncio.get_running_loop()
    watching = loop.create_task(watch.run())
    lines: list[str] = []
    said = asyncio.Event()
    env = env_for(
        config,
        BEYOND_ROS2_CONNECT=f"tcp/127.0.0.1:{port}",
        RMW_IMPLEMENTATION="rmw_zenoh_cpp",
        ROS_DOMAIN_ID="0",
        BEYOND_ROS2_SKELETON=f"{ns}/body_tracking_data",
        BEYOND_ROS2_CAMERA=f"{ns}/camera/image/compressed",
        BEYOND_ROS2_TF="",
        BEYOND_ROS2_CAMERA_RAW="",
    )
    with plain_router(port) as router:
        up = await asyncio.create_subprocess_exec(
            *BEYOND, "up", "--live-source", "beyond_self.services.ros2_source:source",
            "--without", "speech", "--no-live", "--timeout", "60",
            env=env, cwd=tmp_path, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
        )  # fmt: skip
        assert up.stdout is not None and up.stderr is not None

        async def read_lines() -> None:
            assert up.stdout is not None
            async for raw in up.stdout:
                lines.append(raw.decode().rstrip("\n"))
                if ': "' in lines[-1]:
                    said.set()

        reading = loop.create_task(read_lines())
        errors = loop.create_task(up.stderr.read())
        subscribed: set[str] = set()
        source_ready = asyncio.Event()

        def on_token(key: str) -> None:
            subscribed.add(key)
            if len(subscribed) == 2:
                source_ready.set()

        def token(sample: zenoh.Sample) -> None:  # on Zenoh's thread
            if "/MS/" in str(sample.key_expr) and sample.kind == zenoh.SampleKind.PUT:
                loop.call_soon_threadsafe(on_token, str(sample.key_expr))

        # the live source's subscriptions, as `ros2 topic info` sees them: liveliness tokens
        router.liveliness().declare_subscriber("@ros2_lv/0/**", token, history=True)
        session = ZenohSession.get_instance("127.0.0.1", port)
        try:
            assert session.router_port == port  # not another test's session
            sdk_types = session.store.types
            publishers = {
                keys.skeleton: ROS2Publisher(
                    topic=f"{ns}/body_tracking_data", msg_type=r.MARKER_ARRAY,
                    msg_definition=STORE.generate_msgdef(r.MARKER_ARRAY)[0],
                    type_hash=STORE.hash_rihs01(r.MARKER_ARRAY), domain_id=0,
                    router_ip="127.0.0.1", router_port=port,
                ),
                keys.camera: ROS2Publisher(
                    topic=f"{ns}/camera/image/compressed", msg_type=r.COMPRESSED_IMAGE,
                    msg_definition=STORE.generate_msgdef(r.COMPRESSED_IMAGE)[0],
                    type_hash=STORE.hash_rihs01(r.COMPRESSED_IMAGE), domain_id=0,
                    router_ip="127.0.0.1", router_port=port,
                ),
            }  # fmt: skip
            # the live source has subscribed to both topics, and the consumers of both
            # streams report where they are
            await asyncio.wait_for(source_ready.wait(), 30)
            await until(lambda: all(consumers_of(k) for k in publishers), "the consumers")
            consumers = {key: consumers_of(key) for key in publishers}

            def caught_up(key: str, stamp: int) -> Callable[[], bool]:
                return lambda: all(handled[name][key] >= stamp for name in consumers[key])

            for item in read_recording(TOUCH):
                message = item.message()
                stamp = message.header.stamp
                if isinstance(message, SkeletonFrame):
                    key = keys.skeleton
                    publishers[key].publish(**k4abt_markers(sdk_types, message))
                else:
                    assert isinstance(message, CompressedCameraFrame)
                    key = keys.camera
                    publishers[key].publish(**jpeg_image(sdk_types, message))
                await until(caught_up(key, stamp), f"{key} at {stamp}")
            try:
                await asyncio.wait_for(said.wait(), 20)
            except TimeoutError:
                raise AssertionError(f"no sentence 20 s after the last frame: {lines}") from None
            up.send_signal(signal.SIGINT)
            await asyncio.wait_for(up.wait(), 30)
            await reading
        finally:
            if up.returncode is None:
                up.kill()
                await up.wait()
            watching.cancel()
            session.close()
            bus.close()
        stderr = (await errors).decode()
    assert up.returncode == 0, stderr[-3000:]  # stopped as a user stops it, cleanly
    assert frameless(lines) == expected, stderr[-3000:]
