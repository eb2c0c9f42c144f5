"""The ROS 2 bridge, judged by an independent implementation of rmw_zenoh's protocol
(zenoh-ros2-sdk on PyPI: its own key expressions, type hashes, attachment parsing and rosbags
decoding) through a plain Zenoh router: `beyond up --ros2` says each sentence of a recording
once on /<robot>/description, also when the bridge is SIGKILLed in the middle."""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import subprocess
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh
from busutil_net import env_for, free_port, private_config
from ros2util import STORE, zero
from zenoh_ros2_sdk.attachment import Attachment

from beyond_self.runtime.recording.reader import read_recording
from beyond_self.runtime.ros2.node import attachment, read_attachment
from beyond_self.schemas import ros2 as r
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


@contextlib.contextmanager
def plain_router(port: int) -> Iterator[zenoh.Session]:
    """A Zenoh router on loopback, nothing of ours in it (rmw_zenohd's part)."""
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps("router"))
    config.insert_json5("listen/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    config.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(config)
    try:
        yield session
    finally:
        session.close()  # type: ignore[no-untyped-call]


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
    tmp_path: Path,
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
            [*BEYOND, "up", "--recording", str(THREE), "--ros2", "--ros2-connect",
             f"tcp/127.0.0.1:{port}", "--no-live", "--rate", "1", "--timeout", "60"],
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
            listed = dict(get_topic_names_and_types(0, "127.0.0.1", port, timeout=1.0))
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
    said = (tmp_path / "out" / "ros2" / "said.log").read_text().splitlines()
    assert [line.split("\t")[3] for line in said] == heard


async def test_ros2_body_markers_and_camera_are_a_live_source(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The ingest's ROS 2 plug-in reads what a plain Zenoh session publishes on rmw_zenoh's
    data keys in CDR rosbags serialized (no code of ours on that side): the Azure Kinect
    driver's markers (K4ABT ids, no names) become joints under our names, a CompressedImage
    an RGB image."""
    import asyncio

    import numpy as np
    from PIL import Image

    from beyond_self.services.ros2_source import source

    port = free_port()
    robot = "rosbot"
    monkeypatch.setenv("BEYOND_ROBOT", robot)
    monkeypatch.setenv("BEYOND_ROS2_CONNECT", f"tcp/127.0.0.1:{port}")
    monkeypatch.setenv("ROS_DOMAIN_ID", "3")
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
        first = asyncio.ensure_future(anext(items))
        got: list[tuple[str, object, int]] = []
        for _ in range(100):  # until the plug-in's subscriptions are declared
            await asyncio.sleep(0.05)
            tokens = [reply.ok for reply in router.liveliness().get("@ros2_lv/3/**")]
            if sum(1 for tok in tokens if tok is not None and "/MS/" in str(tok.key_expr)) >= 3:
                break
        for key, ros_type, message in samples:
            typed = f"{key}/{r.dds_type(ros_type)}/{STORE.hash_rihs01(ros_type)}"
            router.put(typed, bytes(STORE.serialize_cdr(message, ros_type)))
        got.append(await asyncio.wait_for(first, 10))
        got.append(await asyncio.wait_for(anext(items), 10))
        await items.aclose()
    kinds = {kind: payload for kind, payload, _ in got}
    assert {stamp for _, _, stamp in got} == {1_000_000_005}  # the messages' own stamp
    assert kinds["skeleton"] == {"right_hand": (0.1, 0.2, 1.5, 1.0), "torso": (0.0, 0.0, 2.0, 1.0)}
    camera = kinds["camera"]
    assert isinstance(camera, np.ndarray) and camera.shape == (8, 12, 3)
