"""Our messages to and from ROS 2's standard types in CDR (schemas.ros2 says which), with rosbags'
type store (Jazzy's definitions) doing the serialization and the RIHS01 hashes: a library call
for the bridge and the rosbag2 reader and writer alike, no bus in it. A ROS message carries no
frame index and no header of ours: a stream's frames are numbered 1, 2, ... as they come, and
the header is an original one of source `ros2`."""

from __future__ import annotations

from collections.abc import Callable
from functools import cache
from typing import Any, ClassVar

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from beyond_self.core.errors import InputError
from beyond_self.schemas import ros2 as r
from beyond_self.schemas.base import Message
from beyond_self.schemas.messages import (
    RAW_ENCODINGS,
    CameraFrame,
    CompressedCameraFrame,
    Description,
    Joint,
    SkeletonFrame,
    Time,
)

SOURCE = "ros2"
_NUMPY = {"uint8": np.uint8, "int8": np.int8, "float32": np.float32, "float64": np.float64}


@cache
def store() -> Typestore:
    return get_typestore(Stores.ROS2_JAZZY)


@cache
def type_hash(ros_type: str) -> str:
    """RIHS01 hash of a ROS 2 type, as rosidl computes it (rosbags)."""
    return store().hash_rihs01(ros_type)


@cache
def msgdef(ros_type: str) -> str:
    """The `ros2msg` text of a type with its dependencies (an MCAP schema's data)."""
    return store().generate_msgdef(ros_type, ros_version=2)[0]


@cache
def _defaults(ros_type: str) -> dict[str, Any]:
    """Every field of `ros_type` zero or empty (rosbags needs them all), shared between the
    messages made from them: a field a message sets is given a new value, never changed."""
    return {name: _default_field(node) for name, node in store().fielddefs[ros_type][1]}


def _default(ros_type: str) -> Any:
    return store().types[ros_type](**_defaults(ros_type))


def _default_field(node: Any) -> Any:
    kind, detail = node
    if kind == Nodetype.NAME:
        return _default(detail)
    if kind == Nodetype.BASE:
        base = detail[0]
        return "" if base == "string" else False if base == "bool" else 0
    inner, size = detail
    if inner[0] == Nodetype.BASE and inner[1][0] in _NUMPY:
        return np.zeros(size if kind == Nodetype.ARRAY else 0, dtype=_NUMPY[inner[1][0]])
    return [_default_field(inner) for _ in range(size if kind == Nodetype.ARRAY else 0)]


def _time(ns: int) -> Any:
    return store().types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)


def _header(ns: int, frame_id: str) -> Any:
    return store().types["std_msgs/msg/Header"](stamp=_time(ns), frame_id=frame_id)


def _ns(header: Any) -> int:
    return int(header.stamp.sec) * 10**9 + int(header.stamp.nanosec)


def serialize(ros_type: str, message: Any) -> bytes:
    """CDR with its encapsulation header (little-endian), as on the wire and in rosbag2."""
    return bytes(store().serialize_cdr(message, ros_type))


def deserialize(ros_type: str, data: bytes | memoryview) -> Any:
    try:
        return store().deserialize_cdr(bytes(data), ros_type)
    except Exception as exc:  # rosbags raises assorted errors on short or bad CDR
        raise InputError(f"{ros_type} does not decode as CDR: {exc}") from None


# ---------------------------------------------------------------- ours -> ROS 2
def _stand_ins(tracked: set[str]) -> dict[str, str]:
    """For each K4ABT joint no joint of ours gives, the nearest one that does along the SDK's
    joint hierarchy (ties: the first in K4ABT order), where its untracked marker goes."""
    neighbours: dict[str, list[str]] = {name: [] for name in r.K4ABT_JOINTS}
    for child, parent in r.K4ABT_PARENT.items():
        neighbours[child].append(parent)
        neighbours[parent].append(child)
    out: dict[str, str] = {}
    for name in r.K4ABT_JOINTS:
        if name in tracked:
            continue
        seen, frontier = {name}, [name]
        while frontier and name not in out:
            frontier = sorted(
                {n for f in frontier for n in neighbours[f] if n not in seen},
                key=r.K4ABT_JOINTS.index,
            )
            seen.update(frontier)
            hit = [n for n in frontier if n in tracked]
            if hit:
                out[name] = hit[0]
    return out


def skeleton_markers(frame: SkeletonFrame) -> Any:
    """A skeleton frame as the Azure Kinect driver publishes a body: one sphere marker for each
    of the 32 K4ABT joints, id user*100 + joint, metres, in `depth_camera_link` and its axes
    (schemas.ros2.driver_axes). A joint of ours is its marker with its confidence as alpha; a
    K4ABT joint we have no joint for stands at the nearest one we have, invisible (alpha 0) and
    in namespace `untracked`, which readers of ours skip; a joint of ours with no K4ABT id
    follows the 32, named in `text`."""
    ts = store()
    t = ts.types
    header = _header(frame.header.stamp, r.DRIVER_FRAME)
    base = _defaults("visualization_msgs/msg/Marker")
    scale = t["geometry_msgs/msg/Vector3"](0.05, 0.05, 0.05)
    lifetime = t["builtin_interfaces/msg/Duration"](0, 250_000_000)
    upright = t["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0)

    def marker(index: int, joint: Joint, ns: str = "", text: str = "", alpha: float = 1.0) -> Any:
        point = t["geometry_msgs/msg/Point"](*r.driver_axes(joint.position))
        fields = {
            **base,
            "header": header,
            "ns": ns,
            "id": frame.user * r.BODY_ID_STRIDE + index,
            "type": 2,  # SPHERE
            "pose": t["geometry_msgs/msg/Pose"](point, upright),
            "scale": scale,
            "color": t["std_msgs/msg/ColorRGBA"](0.0, 0.6, 1.0, alpha),
            "lifetime": lifetime,
            "text": text,
        }
        return t["visualization_msgs/msg/Marker"](**fields)

    by_k4abt = {
        k: frame.joints[ours] for k, ours in r.OPENNI_OF_K4ABT.items() if ours in frame.joints
    }
    stand_ins = _stand_ins(set(by_k4abt))
    markers = []
    for index, name in enumerate(r.K4ABT_JOINTS):
        joint = by_k4abt.get(name)
        if joint is not None:
            markers.append(marker(index, joint, alpha=joint.confidence))
        elif name in stand_ins:
            markers.append(marker(index, by_k4abt[stand_ins[name]], r.UNTRACKED, alpha=0.0))
    extra = len(r.K4ABT_JOINTS)
    for name, joint in frame.joints.items():
        if name not in r.K4ABT_OF_OPENNI:
            markers.append(marker(extra, joint, text=name, alpha=joint.confidence))
            extra += 1
    return ts.types[r.MARKER_ARRAY](markers=markers)


def compressed_image(frame: CompressedCameraFrame) -> Any:
    return store().types[r.COMPRESSED_IMAGE](
        header=_header(frame.header.stamp, frame.frame_id),
        format=frame.format,
        data=np.frombuffer(frame.data, dtype=np.uint8),
    )


def raw_image(frame: CameraFrame) -> Any:
    return store().types[r.IMAGE](
        header=_header(frame.header.stamp, frame.frame_id),
        height=frame.height,
        width=frame.width,
        encoding=frame.encoding,
        is_bigendian=0,
        step=frame.step,
        data=np.frombuffer(frame.data, dtype=np.uint8),
    )


def string(text: str) -> Any:
    return store().types[r.STRING](data=text)


def to_ros(stream: str, message: Message) -> tuple[str, bytes] | None:
    """(ROS 2 type, CDR) of a message of ours on `stream`, or None: no standard type carries it
    (a description goes as its best sentence)."""
    if isinstance(message, SkeletonFrame):
        return r.MARKER_ARRAY, serialize(r.MARKER_ARRAY, skeleton_markers(message))
    if isinstance(message, CompressedCameraFrame):
        return r.COMPRESSED_IMAGE, serialize(r.COMPRESSED_IMAGE, compressed_image(message))
    if isinstance(message, CameraFrame):
        return r.IMAGE, serialize(r.IMAGE, raw_image(message))
    if isinstance(message, Description) and message.sentences:
        return r.STRING, serialize(r.STRING, string(message.sentences[0].text))
    return None


# ---------------------------------------------------------------- ROS 2 -> ours
class FromRos:
    """ROS 2 samples of one source into our messages, numbering each stream's frames."""

    def __init__(self) -> None:
        self.count: dict[str, int] = {}
        self._tf: dict[str, tuple[int, str, dict[str, Joint], int]] = {}  # open skeleton frame

    def _next(self, stream: str) -> int:
        n = self.count[stream] = self.count.get(stream, 0) + 1
        return n

    def _head(self, cls: type[Message], stream: str, stamp: int) -> Any:
        return cls.original_header(SOURCE, self._next(stream), stamp, chain=stream)

    def convert(self, stream: str, ros_type: str, data: bytes | memoryview) -> list[Message]:
        """Our messages from one CDR sample of `ros_type` on `stream` (TF frames come out when
        a later stamp closes them: `flush()` gives the last)."""
        handler = self._HANDLERS.get((stream, ros_type))
        if handler is None:
            raise InputError(f"a {ros_type} on the {stream} stream is not read here")
        return handler(self, stream, deserialize(ros_type, data))

    def image(self, ros_type: str, data: bytes | memoryview) -> tuple[int, np.ndarray]:
        """(stamp, RGB pixels) of one Image or CompressedImage sample (for the pose model)."""
        from beyond_self.runtime.recording.images import image_from_message

        read = FromRos._image if ros_type == r.IMAGE else FromRos._compressed
        (message,) = read(self, "pose", deserialize(ros_type, data))
        assert isinstance(message, CameraFrame | CompressedCameraFrame)
        return message.header.stamp, image_from_message(message)

    def _markers(self, stream: str, msg: Any) -> list[Message]:
        """A body-tracking MarkerArray: the first body's joints (id // 100 the body, id % 100
        the K4ABT joint unless `text` names it), in our axes (schemas.ros2.in_our_axes: the
        driver's frame is turned; ours is read as it is); our export's untracked stand-ins are
        skipped."""
        markers = [m for m in msg.markers if m.ns != r.UNTRACKED]
        if not markers:
            return []
        body = min(int(m.id) // r.BODY_ID_STRIDE for m in markers)  # the first body
        first = markers[0].header
        ours = r.in_our_axes(first.frame_id)
        joints: dict[str, Joint] = {}
        for m in markers:
            if int(m.id) // r.BODY_ID_STRIDE != body:
                continue
            p = m.pose.position
            xyz = (float(p.x), float(p.y), float(p.z))
            confidence = min(max(float(m.color.a), 0.0), 1.0)
            joints[r.joint_name(int(m.id), m.text)] = Joint(
                xyz if ours else r.driver_axes(xyz), confidence
            )
        frame = self._next(stream)
        header = SkeletonFrame.original_header(SOURCE, frame, _ns(first), chain=stream)
        frame_id = first.frame_id if ours else r.OUR_FRAMES[0]  # our depth sensor's frame
        return [
            SkeletonFrame(header=header, frame=frame, joints=joints, user=body, frame_id=frame_id)
        ]

    def _compressed(self, stream: str, msg: Any) -> list[Message]:
        stamp = _ns(msg.header)
        fmt = str(msg.format).split(";")[-1].strip().split(" ")[0] or "jpeg"
        return [
            CompressedCameraFrame(
                header=self._head(CompressedCameraFrame, stream, stamp),
                timestamp=Time.from_ns(stamp),
                frame_id=msg.header.frame_id,
                format=fmt,
                data=bytes(msg.data),
            )
        ]

    def _image(self, stream: str, msg: Any) -> list[Message]:
        stamp = _ns(msg.header)
        if msg.encoding not in RAW_ENCODINGS:
            raise InputError(
                f"image encoding {msg.encoding!r} unknown; valid: {', '.join(RAW_ENCODINGS)}"
            )
        return [
            CameraFrame(
                header=self._head(CameraFrame, stream, stamp),
                timestamp=Time.from_ns(stamp),
                frame_id=msg.header.frame_id,
                width=int(msg.width),
                height=int(msg.height),
                encoding=msg.encoding,
                step=int(msg.step),
                data=bytes(msg.data),
            )
        ]

    def _transforms(self, stream: str, msg: Any) -> list[Message]:
        """openni_tracker's joints, one transform each: those of one stamp make a frame."""
        out: list[Message] = []
        for t in msg.transforms:
            found = r.openni_joint(t.child_frame_id)
            if found is None:
                continue
            name, user = found
            stamp = _ns(t.header)
            open_frame = self._tf.get(stream)
            if open_frame is not None and open_frame[0] != stamp:
                out.extend(self.flush())
                open_frame = None
            if open_frame is None:
                open_frame = (stamp, t.header.frame_id.lstrip("/"), {}, user)
                self._tf[stream] = open_frame
            if user == open_frame[3]:
                v = t.transform.translation
                open_frame[2][name] = Joint((float(v.x), float(v.y), float(v.z)), 1.0)
        return out

    def flush(self) -> list[Message]:
        """The skeleton frame still open (TF), if any."""
        out: list[Message] = []
        for stream, (stamp, frame_id, joints, user) in sorted(self._tf.items()):
            frame = self._next("skeleton")
            header = SkeletonFrame.original_header(SOURCE, frame, stamp, chain=stream)
            out.append(
                SkeletonFrame(
                    header=header, frame=frame, joints=joints, user=user, frame_id=frame_id
                )
            )
        self._tf.clear()
        return out

    _HANDLERS: ClassVar[dict[tuple[str, str], Callable[[FromRos, str, Any], list[Message]]]] = {
        ("skeleton", r.MARKER_ARRAY): _markers,
        ("tf", r.TF_MESSAGE): _transforms,
        ("camera_compressed", r.COMPRESSED_IMAGE): _compressed,
        ("person_camera", r.COMPRESSED_IMAGE): _compressed,
        ("camera", r.IMAGE): _image,
    }


def stream_of_ros(stream: str) -> str:
    """The stream of ours a ROS 2 input stream feeds (TF frames are skeleton frames)."""
    return "skeleton" if stream == "tf" else stream
