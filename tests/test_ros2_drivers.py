"""Bags as a real robot's drivers write them and as users have them: the Azure Kinect ROS
driver's conventions (k4a_ros_device.cpp, `getBodyMarker`: bodies on `body_tracking_data`, one
sphere per K4ABT joint, id body*100 + joint, metres, frame `depth_camera_link` in the depth
camera's own axes, x right, y down, z forward; colour as bgra8 on `rgb/image_raw`, or as JPEG
on `rgb/image_raw/compressed` with format "bgra8; jpeg compressed bgr8"), written here with
rosbags' own writer and types, in MCAP and sqlite3 storage (Humble's default), split over
files and zstd-compressed: `beyond analyse BAG` prints the original recording's lines with
no flags."""

from __future__ import annotations

import contextlib
import io
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from ros2util import STORE, zero
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

from beyond_self.cli import main
from beyond_self.runtime.recording.images import image_from_message
from beyond_self.runtime.recording.reader import inspect_recording, read_recording
from beyond_self.schemas import ros2 as r
from beyond_self.schemas.messages import CompressedCameraFrame, SkeletonFrame

RECORDINGS = Path(__file__).resolve().parent.parent / "beyond_self" / "recordings"
SHIPPED = sorted(RECORDINGS.glob("*.mcap"))
T = STORE.types
# the driver's body ids count from 1 (k4abt_body_t.id), its palette's alpha is 1
BODY = 1
# each K4ABT joint's parent (Azure Kinect Body Tracking SDK's joint hierarchy), written out
# here from the SDK's documentation, to place the joints our recordings lack
PARENT = {
    1: 0, 2: 1, 3: 2, 4: 2, 5: 4, 6: 5, 7: 6, 8: 7, 9: 8, 10: 7, 11: 2, 12: 11, 13: 12, 14: 13,
    15: 14, 16: 15, 17: 14, 18: 0, 19: 18, 20: 19, 21: 20, 22: 0, 23: 22, 24: 23, 25: 24,
    26: 3, 27: 26, 28: 26, 29: 26, 30: 26, 31: 26,
}  # fmt: skip
# K4ABT joint id -> our name, for the joints our recordings have (the SDK's names)
K4ABT_IDS = {
    1: "torso", 3: "neck", 5: "left_shoulder", 6: "left_elbow", 8: "left_hand",
    12: "right_shoulder", 13: "right_elbow", 15: "right_hand", 26: "head",
}  # fmt: skip


def _stamp(ns: int) -> Any:
    return T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)


def driver_markers(frame: SkeletonFrame) -> bytes:
    """A body as the driver publishes it: all 32 joints, each in the depth camera's axes (ours
    are x to the person's right, y up, z away: the camera's x is the other way, as is its y).
    A joint our recording lacks takes its nearest ancestor's position that it has."""
    header = T["std_msgs/msg/Header"](
        stamp=_stamp(frame.header.stamp), frame_id="depth_camera_link"
    )
    fields = {n: zero(node) for n, node in STORE.fielddefs["visualization_msgs/msg/Marker"][1]}
    ours = {k: frame.joints[name] for k, name in K4ABT_IDS.items() if name in frame.joints}
    markers = []
    for joint in range(32):
        k = joint
        while k not in ours:
            k = PARENT.get(k, 1)  # the pelvis (0): the spine's navel, the torso
        x, y, z = ours[k].position
        fields.update(
            header=header,
            id=BODY * 100 + joint,
            type=2,  # SPHERE
            action=0,
            pose=T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](-x, -y, z),
                orientation=T["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0),
            ),
            scale=T["geometry_msgs/msg/Vector3"](0.05, 0.05, 0.05),
            color=T["std_msgs/msg/ColorRGBA"](0.0, 1.0, 0.0, 1.0),
        )
        markers.append(T["visualization_msgs/msg/Marker"](**fields))
    return bytes(STORE.serialize_cdr(T[r.MARKER_ARRAY](markers=markers), r.MARKER_ARRAY))


def driver_colour(frame: CompressedCameraFrame, compressed: bool) -> bytes:
    header = T["std_msgs/msg/Header"](stamp=_stamp(frame.header.stamp), frame_id="rgb_camera_link")
    if compressed:
        image = T[r.COMPRESSED_IMAGE](
            header=header,
            format="bgra8; jpeg compressed bgr8",
            data=np.frombuffer(frame.data, np.uint8),
        )
        return bytes(STORE.serialize_cdr(image, r.COMPRESSED_IMAGE))
    rgb = image_from_message(frame)
    h, w = rgb.shape[:2]
    bgra = np.concatenate([rgb[:, :, ::-1], np.full((h, w, 1), 255, np.uint8)], axis=2)
    raw = T[r.IMAGE](
        header=header, height=h, width=w, encoding="bgra8", is_bigendian=0, step=w * 4,
        data=np.ascontiguousarray(bgra).reshape(-1),
    )  # fmt: skip
    return bytes(STORE.serialize_cdr(raw, r.IMAGE))


def depth_image(stamp: int) -> bytes:
    """A tiny 16UC1 depth image, as the driver also publishes (not a colour camera)."""
    header = T["std_msgs/msg/Header"](stamp=_stamp(stamp), frame_id="depth_camera_link")
    raw = T[r.IMAGE](
        header=header, height=2, width=2, encoding="16UC1", is_bigendian=0, step=4,
        data=np.zeros(8, np.uint8),
    )  # fmt: skip
    return bytes(STORE.serialize_cdr(raw, r.IMAGE))


def robot_tf(stamp: int) -> bytes:
    """A robot's own /tf (its base, a wheel): no openni_tracker frames among them."""
    header = T["std_msgs/msg/Header"](stamp=_stamp(stamp), frame_id="base_link")
    transforms = [
        T["geometry_msgs/msg/TransformStamped"](
            header=header,
            child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](
                translation=T["geometry_msgs/msg/Vector3"](0.1, 0.2, 0.3),
                rotation=T["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0),
            ),
        )
        for child in ("camera_base", "wheel_1")
    ]
    return bytes(STORE.serialize_cdr(T[r.TF_MESSAGE](transforms=transforms), r.TF_MESSAGE))


def write_driver_bag(
    recording: Path,
    target: Path,
    *,
    storage: StoragePlugin = StoragePlugin.MCAP,
    compression: CompressionMode | None = None,
    compressed_colour: bool = False,
    namespace: str = "",
    part: tuple[int, int] | None = None,
) -> None:
    """`recording` as the driver's bag at `target` (`part` (i, n): the i-th n-th of it)."""
    items = list(read_recording(recording))
    if part is not None:
        i, n = part
        items = items[len(items) * i // n : len(items) * (i + 1) // n]
    writer = Writer(target, version=9, storage_plugin=storage)
    if compression is not None:
        writer.set_compression(compression, CompressionFormat.ZSTD)
    colour_topic = f"{namespace}/rgb/image_raw" + ("/compressed" if compressed_colour else "")
    colour_type = r.COMPRESSED_IMAGE if compressed_colour else r.IMAGE
    with writer:
        bodies = writer.add_connection(
            f"{namespace}/body_tracking_data", r.MARKER_ARRAY, typestore=STORE
        )
        colour = writer.add_connection(colour_topic, colour_type, typestore=STORE)
        depth = writer.add_connection(f"{namespace}/depth/image_raw", r.IMAGE, typestore=STORE)
        tf = writer.add_connection("/tf", r.TF_MESSAGE, typestore=STORE)
        writer.write(tf, items[0].log_time, robot_tf(items[0].message().header.stamp))
        for item in items:
            msg = item.message()
            if isinstance(msg, SkeletonFrame):
                writer.write(bodies, item.log_time, driver_markers(msg))
            elif isinstance(msg, CompressedCameraFrame):
                writer.write(colour, item.log_time, driver_colour(msg, compressed_colour))
                writer.write(depth, item.log_time, depth_image(msg.header.stamp))


def split_bag(recording: Path, target: Path, parts: int = 2) -> None:
    """The bag split over `parts` MCAP files as rosbag2 splits one (`--max-bag-size`): files
    `<name>_<i>.mcap`, one metadata.yaml listing them in order, with each file's counts."""
    infos: list[dict[str, Any]] = []
    target.mkdir()
    for i in range(parts):
        piece = target.parent / f"{target.name}.part{i}"
        write_driver_bag(recording, piece, part=(i, parts))
        info = yaml.safe_load((piece / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        (name,) = info["relative_file_paths"]
        shutil.move(piece / name, target / f"{target.name}_{i}.mcap")
        infos.append(info)
        shutil.rmtree(piece)
    merged = infos[0]
    merged["relative_file_paths"] = [f"{target.name}_{i}.mcap" for i in range(parts)]
    merged["files"] = [
        {**info["files"][0], "path": f"{target.name}_{i}.mcap"} for i, info in enumerate(infos)
    ]
    merged["message_count"] = sum(info["message_count"] for info in infos)
    start = min(info["starting_time"]["nanoseconds_since_epoch"] for info in infos)
    end = max(
        info["starting_time"]["nanoseconds_since_epoch"] + info["duration"]["nanoseconds"]
        for info in infos
    )
    merged["starting_time"]["nanoseconds_since_epoch"] = start
    merged["duration"]["nanoseconds"] = end - start
    for k, topic in enumerate(merged["topics_with_message_count"]):
        topic["message_count"] = sum(
            info["topics_with_message_count"][k]["message_count"] for info in infos
        )
    (target / "metadata.yaml").write_text(yaml.safe_dump({"rosbag2_bagfile_information": merged}))


def beyond(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


def gesture_lines(path: Path, *flags: str) -> tuple[list[str], str]:
    code, out, err = beyond("analyse", str(path), *flags)
    assert code == 0, err
    return [line for line in out.splitlines() if line.startswith("gesture ")], err


@pytest.fixture(scope="module")
def originals() -> dict[str, list[str]]:
    """`beyond analyse` of each shipped recording: its gesture lines (two and more each)."""
    lines = {path.stem: gesture_lines(path)[0] for path in SHIPPED}
    assert len(lines) == 3 and all(len(v) >= 2 for v in lines.values()), lines
    return lines


@pytest.mark.slow
@pytest.mark.parametrize(
    "storage", [StoragePlugin.MCAP, StoragePlugin.SQLITE3], ids=["mcap", "sqlite3"]
)
@pytest.mark.parametrize("recording", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_an_azure_kinect_drivers_bag_analyses_as_the_original(
    tmp_path: Path, recording: Path, storage: StoragePlugin, originals: dict[str, list[str]]
) -> None:
    bag = tmp_path / "k4a"
    write_driver_bag(recording, bag, storage=storage)
    lines, err = gesture_lines(bag)
    assert lines == originals[recording.stem]
    # the driver's depth image is no colour camera: named, with the option that would map it
    assert "ROS 2 topics not read: /depth/image_raw (sensor_msgs/msg/Image)" in err
    assert "e.g. --topic camera=/depth/image_raw" in err


@pytest.mark.slow
@pytest.mark.parametrize("how", ["split", "zstd-file", "zstd-message", "compressed-colour"])
def test_bags_as_users_have_them_analyse_as_the_original(
    tmp_path: Path, how: str, originals: dict[str, list[str]]
) -> None:
    """Split over two files, zstd-compressed per file (`ros2 bag record
    --compression-mode file`) or per message, and the driver's JPEG colour topic."""
    recording = RECORDINGS / "tap-ball-grasp-box.mcap"
    bag = tmp_path / "k4a"
    if how == "split":
        split_bag(recording, bag)
        assert len(list(bag.glob("*.mcap"))) == 2
    elif how == "compressed-colour":
        write_driver_bag(recording, bag, compressed_colour=True, namespace="/k4a")
    else:
        mode = CompressionMode.FILE if how == "zstd-file" else CompressionMode.MESSAGE
        write_driver_bag(recording, bag, compression=mode)
    assert gesture_lines(bag)[0] == originals[recording.stem]


def test_a_drivers_body_is_turned_into_our_axes(tmp_path: Path) -> None:
    """The driver's joints, x right, y down in the camera's image, become ours (x to the
    person's right, y up): its head above its torso again, its right hand on the +x side, under
    our joint names; a marker in a frame of ours is read as it is."""
    recording = RECORDINGS / "touch-box.mcap"
    bag = tmp_path / "k4a"
    write_driver_bag(recording, bag)
    original = [
        m for m in (i.message() for i in read_recording(recording)) if isinstance(m, SkeletonFrame)
    ]
    read = [m for m in (i.message() for i in read_recording(bag)) if isinstance(m, SkeletonFrame)]
    assert len(read) == len(original) > 100
    for ours, theirs in zip(original, read, strict=True):
        assert theirs.header.stamp == ours.header.stamp and theirs.user == BODY
        assert len(theirs.joints) == 32
        for name, joint in ours.joints.items():
            assert np.allclose(theirs.joints[name].position, joint.position, atol=1e-9), name


def test_inspect_prints_a_bags_topics_as_a_table(tmp_path: Path) -> None:
    bag = tmp_path / "k4a"
    write_driver_bag(RECORDINGS / "touch-box.mcap", bag, storage=StoragePlugin.SQLITE3)
    code, out, err = beyond("inspect", str(bag))
    assert code == 0, err
    assert "serialized_metadata" not in out and "\\n" not in out
    skeletons = sum(
        1 for i in read_recording(RECORDINGS / "touch-box.mcap") if i.key.endswith("skeleton")
    )
    rows = {
        line.split()[0]: line.split()[1:] for line in out.splitlines() if line.startswith("  /")
    }
    assert rows["/body_tracking_data"][:2] == [r.MARKER_ARRAY, str(skeletons)]
    assert rows["/rgb/image_raw"][0] == r.IMAGE
    assert rows["/depth/image_raw"][0] == r.IMAGE and "not read" in " ".join(
        rows["/depth/image_raw"]
    )
    info = inspect_recording(bag)
    assert [c.count for c in info.channels if c.topic.endswith("skeleton")] == [skeletons]


def test_a_topic_is_mapped_by_hand(tmp_path: Path) -> None:
    """`--topic camera=/depth/image_raw` reads the depth image as the camera (refused when
    analysed: no colour), and names the colour topic not read; a topic the bag lacks or of the
    wrong type is refused up front."""
    bag = tmp_path / "k4a"
    write_driver_bag(RECORDINGS / "touch-box.mcap", bag)
    code, _, err = beyond("analyse", str(bag), "--topic", "skeleton=/rgb/image_raw")
    assert code == 2 and "--topic skeleton=/rgb/image_raw: a sensor_msgs/msg/Image" in err
    code, _, err = beyond("analyse", str(RECORDINGS / "touch-box.mcap"), "--topic", "tf=/tf")
    assert code == 2 and "--topic maps a ROS 2 bag's topics;" in err
    code, _, err = beyond("analyse", str(bag), "--topic", "camera=/nope")
    assert code == 2 and "--topic camera=/nope: no such topic" in err
    code, _, err = beyond("analyse", str(bag), "--topic", "camera=/depth/image_raw")
    assert code == 2 and "camera encoding 16UC1 is not a colour image" in err
    assert "ROS 2 topics not read: /rgb/image_raw (sensor_msgs/msg/Image)" in err


@pytest.mark.slow
def test_an_rgb_only_robots_bag_goes_through_the_pose_model(tmp_path: Path) -> None:
    """A bag with one camera and no skeleton (usb_cam's `image_raw`, rgb8, as most robots
    have) is a camera watching a person: read through the pose model, it is what `beyond
    video` records of the same frames with the same stamps, skeleton for skeleton, and
    `beyond analyse` prints the same lines."""
    from pose_media import carphone

    from beyond_self.cognition.pose.video import Video
    from beyond_self.cognition.scene import EPOCH_NS

    recorded = tmp_path / "carphone.mcap"
    assert beyond("video", str(carphone()), "-o", str(recorded))[0] == 0
    bag = tmp_path / "usb_cam"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        camera = writer.add_connection("/usb_cam/image_raw", r.IMAGE, typestore=STORE)
        with Video(carphone()) as video:
            for frame in video.frames():
                stamp = EPOCH_NS + frame.time_ns
                h, w = frame.rgb.shape[:2]
                header = T["std_msgs/msg/Header"](stamp=_stamp(stamp), frame_id="camera")
                image = T[r.IMAGE](
                    header=header, height=h, width=w, encoding="rgb8", is_bigendian=0,
                    step=w * 3, data=np.ascontiguousarray(frame.rgb).reshape(-1),
                )  # fmt: skip
                writer.write(camera, stamp, bytes(STORE.serialize_cdr(image, r.IMAGE)))

    def skeletons(path: Path) -> list[SkeletonFrame]:
        return [
            m for m in (i.message() for i in read_recording(path)) if isinstance(m, SkeletonFrame)
        ]

    ours, theirs = skeletons(recorded), skeletons(bag)
    assert len(theirs) == len(ours) > 100
    for a, b in zip(ours, theirs, strict=True):
        assert a.header.stamp == b.header.stamp and a.joints.keys() == b.joints.keys()
        for name, joint in a.joints.items():
            assert np.allclose(b.joints[name].position, joint.position, atol=1e-9), name
    code, out, err = beyond("analyse", str(bag))
    assert code == 0, err
    assert out == beyond("analyse", str(recorded))[1]
    code, out, err = beyond("inspect", str(bag))
    assert code == 0 and "read as pose" in out, err


IMG, C = r.IMAGE, r.COMPRESSED_IMAGE
TF, M = r.TF_MESSAGE, r.MARKER_ARRAY


@pytest.mark.parametrize(
    ("topics", "roles", "routes"),
    [
        # the Azure Kinect driver, with a robot's /tf: the markers are the skeleton
        ({"/k4a/body_tracking_data": M, "/k4a/rgb/image_raw": IMG, "/k4a/depth/image_raw": IMG,
          "/tf": TF}, {},
         {"/k4a/body_tracking_data": ("k4a", "skeleton"), "/k4a/rgb/image_raw": ("k4a", "camera")}),
        # usb_cam on a robot: RGB-only, through the pose model; its /tf is no skeleton
        ({"/usb_cam/image_raw": IMG, "/usb_cam/image_raw/compressed": C, "/tf": TF}, {},
         {"/usb_cam/image_raw": ("robot", "pose")}),
        # RealSense's colour beside its depth: the colour one, by its name
        ({"/camera/color/image_raw": IMG, "/camera/depth/image_rect_raw": IMG}, {},
         {"/camera/color/image_raw": ("robot", "pose")}),
        # two colour cameras: neither is guessed
        ({"/left/image_raw": IMG, "/right/image_raw": IMG}, {}, {}),
        # openni_tracker beside our tabletop camera
        ({"/tf": TF, "/robot/camera/image/compressed": C}, {},
         {"/tf": ("robot", "tf"),
          "/robot/camera/image/compressed": ("robot", "camera_compressed")}),
        # mapped by hand: a TF skeleton and a camera found by its type
        ({"/tf": TF, "/usb_cam/image_raw": IMG}, {"tf": "/tf"},
         {"/tf": ("robot", "tf"), "/usb_cam/image_raw": ("robot", "camera")}),
        ({"/left/image_raw": IMG, "/right/image_raw": IMG}, {"person_camera": "/left/image_raw"},
         {"/left/image_raw": ("robot", "pose")}),
    ],
)  # fmt: skip
def test_topics_are_planned_as_robots_publish_them(
    topics: dict[str, str], roles: dict[str, str], routes: dict[str, tuple[str, str]]
) -> None:
    from beyond_self.runtime.ros2.topics import plan

    planned = plan(topics, roles)
    assert planned.routes == routes
    assert set(planned.unread) == set(topics) - set(routes)
    if planned.unread:
        assert planned.note().startswith("ROS 2 topics not read: ")


@pytest.mark.slow
@pytest.mark.timeout(180)
def test_up_plays_a_drivers_bag_as_analyse_reads_it(
    tmp_path: Path, originals: dict[str, list[str]]
) -> None:
    """`beyond up --recording BAG` of a driver's sqlite3 bag prints the original's lines."""
    import subprocess

    from busutil_net import env_for, private_config

    from beyond_self.services.launcher import BEYOND

    recording = RECORDINGS / "touch-box.mcap"
    bag = tmp_path / "k4a"
    write_driver_bag(recording, bag, storage=StoragePlugin.SQLITE3)
    env = {**env_for(private_config()), "BEYOND_LOG_FORMAT": "text"}
    cmd = [*BEYOND, "up", "--recording", str(bag), "--rate", "0", "--no-live", "--timeout", "60"]
    up = subprocess.run(cmd, env=env, cwd=tmp_path, capture_output=True, text=True, timeout=150)
    assert up.returncode == 0, up.stderr[-3000:]
    lines = [line for line in up.stdout.splitlines() if line.startswith("gesture ")]
    assert lines == originals[recording.stem]
