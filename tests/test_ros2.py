"""ROS 2: rmw_zenoh's key expressions as its design document writes them, and rosbag2 bags as
recordings, judged by third-party readers (rosbags, mcap-ros2-support) and by `beyond analyse`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.reader import read_ros2_messages
from ros2util import STORE, zero
from rosbags.rosbag2 import Reader, StoragePlugin, Writer

from beyond_self.cli import main
from beyond_self.core.errors import InputError
from beyond_self.runtime.recording.reader import inspect_recording, read_recording
from beyond_self.runtime.ros2.bag_export import export
from beyond_self.schemas import ros2 as r
from beyond_self.schemas.messages import CompressedCameraFrame, SkeletonFrame

RECORDINGS = Path(__file__).resolve().parent.parent / "recordings"
THREE = RECORDINGS / "three-actions.mcap"
STRING_HASH = STORE.hash_rihs01("std_msgs/msg/String")

# ros2/rmw_zenoh docs/design.md, "Topic and Service name mapping" and "Graph Cache"
DESIGN_CHATTER_KEY = (
    "0/chatter/std_msgs::msg::dds_::String_/"
    "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
)
DESIGN_TALKER_TOKEN = (
    "@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/"
    "std_msgs::msg::dds_::String_/"
    "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,7:,:,:,,"
)
DESIGN_LISTENER_NODE = "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"


def test_data_key_is_the_design_documents_example() -> None:
    assert r.data_key(0, "/chatter", r.STRING, STRING_HASH) == DESIGN_CHATTER_KEY


def test_liveliness_tokens_are_the_design_documents_examples() -> None:
    session = "8b20917502ee955ac4476e0266340d5c"
    token = r.endpoint_token(
        r.PUBLISHER, 2, session, 0, 10, "/", "talker", "/chatter", r.STRING, STRING_HASH,
        r.Qos(depth=7),
    )  # fmt: skip
    assert token == DESIGN_TALKER_TOKEN
    listener = r.node_token(2, "aac3178e146ba6f1fc6e6a4085e77f21", 0, "/", "listener")
    assert listener == DESIGN_LISTENER_NODE
    assert r.SENSOR_QOS.keyexpr() == "2::,5:,:,:,,"  # best effort, depth 5


def test_topics_are_ros_names_under_the_robot() -> None:
    topics = r.Ros2Topics("lab-1", {"description": "/tts/say", "person_camera": "eyes"})
    assert topics.topic("description") == "/tts/say"
    assert topics.topic("person_camera") == "/lab_1/eyes"
    assert topics.topic("skeleton") == "/lab_1/body_tracking_data"
    assert topics.topic("tf") == "/tf"
    for bad in ("", "/a//b", "/9lives", "/a-b"):
        with pytest.raises(InputError, match="invalid ROS 2 topic name"):
            r.check_topic(bad)


def _analyse(path: Path, capsys: pytest.CaptureFixture[str]) -> list[str]:
    capsys.readouterr()
    assert main(["analyse", str(path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert any(line.startswith("gesture 3:") for line in lines)  # something to compare
    return lines


@pytest.fixture(scope="module")
def original_lines() -> list[str]:
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["analyse", str(THREE)]) == 0
    return out.getvalue().splitlines()


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> Path:
    bag = tmp_path_factory.mktemp("export") / "three"
    assert main(["ros2", "export", str(THREE), "-o", str(bag)]) == 0
    return bag


def test_exported_bag_analyses_as_the_original(
    exported: Path, original_lines: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert _analyse(exported, capsys) == original_lines
    bare = inspect_recording(exported / "three.mcap")  # the bare MCAP reads as the folder
    assert (
        [(c.topic, c.count) for c in bare.channels]
        == [(c.topic, c.count) for c in inspect_recording(exported).channels]
        == [(c.topic, c.count) for c in inspect_recording(THREE).channels]
    )


def test_third_party_readers_read_every_message(exported: Path) -> None:
    ours = sum(1 for _ in read_recording(THREE))
    with Reader(exported) as reader:  # rosbags, against its own type store
        decoded = [STORE.deserialize_cdr(raw, c.msgtype) for c, _, raw in reader.messages()]
        topics = {c.topic: c.msgtype for c in reader.connections}
    assert len(decoded) == ours == 987
    assert topics == {
        "/robot/body_tracking_data": r.MARKER_ARRAY,
        "/robot/camera/image/compressed": r.COMPRESSED_IMAGE,
    }
    mcap = exported / "three.mcap"
    assert sum(1 for _ in read_ros2_messages(str(mcap))) == ours  # mcap-ros2-support
    with open(mcap, "rb") as f:
        reader2 = make_reader(f)
        assert reader2.get_header().profile == "ros2"
        summary = reader2.get_summary()
        assert summary is not None
        for channel in summary.channels.values():
            schema = summary.schemas[channel.schema_id]
            assert (schema.encoding, channel.message_encoding) == ("ros2msg", "cdr")
            assert channel.metadata["topic_type_hash"] == STORE.hash_rihs01(schema.name)
            qos = yaml.safe_load(channel.metadata["offered_qos_profiles"])
            assert qos[0]["reliability"] == "best_effort" and qos[0]["depth"] == 5


def _rosbags_bag(target: Path, *, tf: bool) -> None:
    """Three-actions written by rosbags' own writer from messages built here with rosbags'
    types, as the Azure Kinect driver (markers numbered by K4ABT joint, no names) or
    openni_tracker (one transform per joint) and an image_transport camera publish them."""
    t = STORE.types
    with Writer(target, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        body_type = r.TF_MESSAGE if tf else r.MARKER_ARRAY
        body_topic = "/tf" if tf else "/robot/body_tracking_data"
        body = writer.add_connection(body_topic, body_type, typestore=STORE)
        cam = writer.add_connection(
            "/robot/camera/image/compressed", r.COMPRESSED_IMAGE, typestore=STORE
        )
        k4abt = {ours: r.K4ABT_JOINTS.index(k) for k, ours in r.OPENNI_OF_K4ABT.items()}
        for item in read_recording(THREE):
            msg = item.message()
            stamp = t["builtin_interfaces/msg/Time"](
                sec=msg.header.stamp // 10**9, nanosec=msg.header.stamp % 10**9
            )
            if isinstance(msg, CompressedCameraFrame):
                header = t["std_msgs/msg/Header"](stamp=stamp, frame_id=msg.frame_id)
                image = t[r.COMPRESSED_IMAGE](
                    header=header, format="jpeg", data=np.frombuffer(msg.data, np.uint8)
                )
                writer.write(cam, item.log_time, STORE.serialize_cdr(image, r.COMPRESSED_IMAGE))
                continue
            assert isinstance(msg, SkeletonFrame)
            for name, joint in msg.joints.items():
                header = t["std_msgs/msg/Header"](stamp=stamp, frame_id=msg.frame_id)
                if tf:
                    one = t["geometry_msgs/msg/TransformStamped"](
                        header=header,
                        child_frame_id=f"{name}_1",
                        transform=t["geometry_msgs/msg/Transform"](
                            translation=t["geometry_msgs/msg/Vector3"](*joint.position),
                            rotation=t["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0),
                        ),
                    )
                    data = STORE.serialize_cdr(t[r.TF_MESSAGE](transforms=[one]), r.TF_MESSAGE)
                    writer.write(body, item.log_time, data)
            if not tf:
                writer.write(body, item.log_time, _markers(msg, header, k4abt))


def _markers(msg: SkeletonFrame, header: object, k4abt: dict[str, int]) -> bytes:
    t = STORE.types
    markers = []
    for name, joint in msg.joints.items():
        fields = {n: zero(node) for n, node in STORE.fielddefs["visualization_msgs/msg/Marker"][1]}
        fields.update(
            header=header,
            id=100 + k4abt[name],
            type=2,
            pose=t["geometry_msgs/msg/Pose"](
                position=t["geometry_msgs/msg/Point"](*joint.position),
                orientation=t["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0),
            ),
            color=t["std_msgs/msg/ColorRGBA"](1.0, 0.0, 0.0, joint.confidence),
        )
        markers.append(t["visualization_msgs/msg/Marker"](**fields))
    array = t[r.MARKER_ARRAY](markers=markers)
    return bytes(STORE.serialize_cdr(array, r.MARKER_ARRAY))


@pytest.mark.parametrize("tf", [False, True], ids=["azure-kinect-markers", "openni-tf"])
def test_a_bag_written_by_rosbags_analyses_as_the_original(
    tmp_path: Path, tf: bool, original_lines: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "bag"
    _rosbags_bag(bag, tf=tf)
    assert _analyse(bag, capsys) == original_lines


def test_a_truncated_bag_is_read_up_to_its_damage(
    exported: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The damaged-file policy of our own recordings: what is readable is read, the loss is
    said on one line and the command exits 2."""
    data = (exported / "three.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    capsys.readouterr()
    assert main(["inspect", str(cut)]) == 2
    said = capsys.readouterr()
    assert "beyond/robot/sensors/skeleton" in said.out
    assert "is damaged: truncated at byte" in said.err and "played the other" in said.err
    assert main(["analyse", str(cut)]) == 2
    said = capsys.readouterr()
    assert "is damaged: truncated" in said.err


def test_export_refuses_an_existing_folder(exported: Path) -> None:
    with pytest.raises(Exception, match="exists"):
        export(THREE, exported)
