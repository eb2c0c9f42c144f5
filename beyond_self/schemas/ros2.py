"""The ROS 2 face of a deployment: topic names, standard message types and rmw_zenoh's key
expressions (ros2/rmw_zenoh docs/design.md), defined once. A stream of ours maps to one ROS 2
topic under the robot's namespace (`/<robot>/...`) with the nearest standard type; the CDR
conversion is runtime.ros2.convert's, the type hashes (RIHS01) come from rosbags' type store.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass, field

from beyond_self.core.errors import InputError
from beyond_self.schemas.keys import check_name

DEFAULT_CONNECT = "tcp/127.0.0.1:7447"  # rmw_zenoh's router (rmw_zenohd)
STRING = "std_msgs/msg/String"
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
IMAGE = "sensor_msgs/msg/Image"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"

# stream name (schemas.keys.STREAMS) -> (topic relative to /<robot>, ROS 2 type): the defaults
# of the topic options. The skeleton is the Azure Kinect ROS driver's `body_tracking_data`
# (one sphere marker per joint, id = body id * 100 + joint); cameras follow image_transport.
TOPICS: dict[str, tuple[str, str]] = {
    "skeleton": ("body_tracking_data", MARKER_ARRAY),
    "camera": ("camera/image", IMAGE),
    "camera_compressed": ("camera/image/compressed", COMPRESSED_IMAGE),
    "person_camera": ("person/image/compressed", COMPRESSED_IMAGE),
    "description": ("description", STRING),
}
# openni_tracker's frames: one transform per joint and user (`right_hand_1`), on /tf
TF_TOPIC = "/tf"
OPENNI_FRAME = "openni_depth_frame"

# Azure Kinect Body Tracking SDK's joints (k4abt_joint_id_t), in id order
K4ABT_JOINTS = (
    "pelvis", "spine_navel", "spine_chest", "neck", "clavicle_left", "shoulder_left",
    "elbow_left", "wrist_left", "hand_left", "handtip_left", "thumb_left", "clavicle_right",
    "shoulder_right", "elbow_right", "wrist_right", "hand_right", "handtip_right",
    "thumb_right", "hip_left", "knee_left", "ankle_left", "foot_left", "hip_right",
    "knee_right", "ankle_right", "foot_right", "head", "nose", "eye_left", "ear_left",
    "eye_right", "ear_right",
)  # fmt: skip
# our (OpenNI) joint names for the K4ABT joints that have one
OPENNI_OF_K4ABT = {
    "head": "head", "neck": "neck", "spine_navel": "torso",
    "shoulder_left": "left_shoulder", "elbow_left": "left_elbow", "hand_left": "left_hand",
    "shoulder_right": "right_shoulder", "elbow_right": "right_elbow", "hand_right": "right_hand",
    "hip_left": "left_hip", "knee_left": "left_knee", "foot_left": "left_foot",
    "hip_right": "right_hip", "knee_right": "right_knee", "foot_right": "right_foot",
}  # fmt: skip
K4ABT_OF_OPENNI = {ours: K4ABT_JOINTS.index(k) for k, ours in OPENNI_OF_K4ABT.items()}
OPENNI_JOINTS = frozenset(OPENNI_OF_K4ABT.values())  # openni_tracker's 15 frames
BODY_ID_STRIDE = 100  # marker id = body id * 100 + joint id (the driver's numbering)
# each K4ABT joint's parent in the SDK's joint hierarchy (the pelvis is the root)
K4ABT_PARENT = {
    "spine_navel": "pelvis", "spine_chest": "spine_navel", "neck": "spine_chest",
    "clavicle_left": "spine_chest", "shoulder_left": "clavicle_left",
    "elbow_left": "shoulder_left", "wrist_left": "elbow_left", "hand_left": "wrist_left",
    "handtip_left": "hand_left", "thumb_left": "wrist_left", "clavicle_right": "spine_chest",
    "shoulder_right": "clavicle_right", "elbow_right": "shoulder_right",
    "wrist_right": "elbow_right", "hand_right": "wrist_right", "handtip_right": "hand_right",
    "thumb_right": "wrist_right", "hip_left": "pelvis", "knee_left": "hip_left",
    "ankle_left": "knee_left", "foot_left": "ankle_left", "hip_right": "pelvis",
    "knee_right": "hip_right", "ankle_right": "knee_right", "foot_right": "ankle_right",
    "head": "neck", "nose": "head", "eye_left": "head", "ear_left": "head",
    "eye_right": "head", "ear_right": "head",
}  # fmt: skip

# The Azure Kinect ROS driver (and Orbbec's K4A wrapper) stamps body markers with its depth
# camera's frame, `depth_camera_link`, whose axes are the camera's own (K4A's depth camera
# coordinates, as any `*_optical_frame`): x right in the image, y down, z forward, metres.
# Ours (the OpenNI skeletons the gesture models read) have x to the person's right, which is
# the image's left for a person facing the camera, y up, z away: a half turn about z, its own
# inverse. Skeleton frames of ours carry one of OUR_FRAMES; any other marker frame is read in
# the driver's axes.
DRIVER_FRAME = "depth_camera_link"
OUR_FRAMES = ("depth_camera", "person")
UNTRACKED = "untracked"  # the `ns` of an exported marker standing in for a joint we lack


def driver_axes(xyz: tuple[float, float, float]) -> tuple[float, float, float]:
    """A point in our axes in the driver's, or back (the same half turn about z)."""
    x, y, z = xyz
    return (-x, -y, z)


def in_our_axes(frame_id: str) -> bool:
    """Whether a marker frame is one of ours (read as it is) rather than a camera's."""
    return frame_id.lstrip("/") in OUR_FRAMES


def joint_name(marker_id: int, text: str) -> str:
    """Our name of a body marker's joint: its `text` when set (our export writes it), else the
    K4ABT joint of `id % 100` (OpenNI's name where one exists)."""
    if text:
        return text
    index = marker_id % BODY_ID_STRIDE
    if index >= len(K4ABT_JOINTS):
        raise InputError(
            f"body marker id {marker_id} names no joint; "
            f"valid: body*100 + 0..{len(K4ABT_JOINTS) - 1}"
        )
    k4abt = K4ABT_JOINTS[index]
    return OPENNI_OF_K4ABT.get(k4abt, k4abt)


def openni_joint(child_frame_id: str) -> tuple[str, int] | None:
    """(joint, user) of an openni_tracker frame (`right_hand_1`: one of its 15 joints), else
    None (a robot's own frames on /tf, `wheel_1`, are none of them)."""
    name, _, user = child_frame_id.lstrip("/").rpartition("_")
    return (name, int(user)) if name in OPENNI_JOINTS and user.isdigit() else None


@dataclass(frozen=True)
class Ros2Topics:
    """The ROS 2 topics of one robot: `/<robot>/<relative>` for each stream (TOPICS; the
    robot's name as a ROS name, ros_name), with any of them renamed (an absolute name is kept
    as it is)."""

    robot: str
    renamed: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_name("robot", self.robot)
        for stream, name in self.renamed.items():
            if stream not in TOPICS and stream != "tf":
                raise InputError(
                    f"no ROS 2 topic for stream {stream!r}; valid: {', '.join(TOPICS)}, tf"
                )
            check_topic(name)

    def topic(self, stream: str) -> str:
        name = self.renamed.get(stream, TF_TOPIC if stream == "tf" else TOPICS[stream][0])
        return name if name.startswith("/") else f"/{ros_name(self.robot)}/{name}"

    def streams(self) -> dict[str, str]:
        """Fully qualified topic -> stream, for every stream with a topic (tf included)."""
        return {self.topic(s): s for s in (*TOPICS, "tf")}


def ros_name(name: str) -> str:
    """A robot or service name as a ROS 2 name token (letters, digits, '_')."""
    token = re.sub(r"[^A-Za-z0-9_]", "_", name)
    return token if token[:1].isalpha() or token[:1] == "_" else f"_{token}"


def check_topic(name: str) -> str:
    """A ROS 2 topic name (letters, digits, '_' and '/' separators, no empty token)."""
    tokens = name.strip("/").split("/")
    if (
        not name
        or any(not t or not (t[0].isalpha() or t[0] == "_") for t in tokens)
        or any(not all(c.isalnum() or c == "_" for c in t) for t in tokens)
    ):
        raise InputError(
            f"invalid ROS 2 topic name {name!r}; valid: tokens of letters, digits and '_' "
            "separated by '/', none starting with a digit"
        )
    return name


# ---------------------------------------------------------------- rmw_zenoh key expressions
LIVELINESS_PREFIX = "@ros2_lv"
NODE, PUBLISHER, SUBSCRIPTION = "NN", "MP", "MS"


def dds_type(ros_type: str) -> str:
    """`std_msgs/msg/String` -> `std_msgs::msg::dds_::String_` (the type name in the keys)."""
    package, kind, name = ros_type.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def data_key(domain: int, topic: str, ros_type: str, type_hash: str) -> str:
    """`<domain>/<topic without leading/trailing '/'>/<dds type>/<RIHS01 hash>`."""
    return f"{domain}/{topic.strip('/')}/{dds_type(ros_type)}/{type_hash}"


def mangle(name: str) -> str:
    """A name as one key chunk: every '/' a '%' (the empty namespace is `%`)."""
    return name.replace("/", "%") or "%"


@dataclass(frozen=True)
class Qos:
    """The QoS a liveliness token advertises: what differs from rmw_zenoh's default (reliable,
    volatile, keep-last 42, infinite durations, automatic liveliness) is written, the rest
    left empty, as rmw_zenoh's `qos_to_keyexpr` does."""

    reliable: bool = True
    transient_local: bool = False
    depth: int = 10

    def keyexpr(self) -> str:
        reliability = "" if self.reliable else "2"  # RMW_QOS_POLICY_RELIABILITY_BEST_EFFORT
        durability = "1" if self.transient_local else ""  # ..._DURABILITY_TRANSIENT_LOCAL
        depth = "" if self.depth == 42 else str(self.depth)
        return f"{reliability}:{durability}:,{depth}:,:,:,,"


RELIABLE_QOS = Qos()  # descriptions: a TTS node must get every one
SENSOR_QOS = Qos(reliable=False, depth=5)  # rclcpp's SensorDataQoS


def node_token(domain: int, session: str, node_id: int, namespace: str, node: str) -> str:
    return "/".join(
        (LIVELINESS_PREFIX, str(domain), session, str(node_id), str(node_id), NODE, "%",
         mangle(namespace), node)
    )  # fmt: skip


def endpoint_token(
    kind: str,
    domain: int,
    session: str,
    node_id: int,
    entity_id: int,
    namespace: str,
    node: str,
    topic: str,
    ros_type: str,
    type_hash: str,
    qos: Qos,
) -> str:
    """The liveliness token of a publisher (MP) or subscription (MS) of node `node`."""
    return "/".join(
        (LIVELINESS_PREFIX, str(domain), session, str(node_id), str(entity_id), kind, "%",
         mangle(namespace), node, mangle(topic), dds_type(ros_type), type_hash, qos.keyexpr())
    )  # fmt: skip


def gid(token: str) -> bytes:
    """A 16-byte endpoint GID from its liveliness token (rmw_zenoh hashes the token too, with
    XXH3-128; any stable 16 bytes unique per endpoint serve a receiver)."""
    return hashlib.blake2b(token.encode(), digest_size=16).digest()
