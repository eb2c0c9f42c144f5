"""Which ROS 2 topics of a bag (or graph) feed which stream of ours, decided once over all its
topics: what a user maps with `--topic ROLE=/name` first, then our own names and the Azure
Kinect driver's (`body_tracking_data`, `rgb/image_raw[/compressed]`, openni_tracker's `/tf`),
then a camera found by its type alone. A robot with a camera and no skeleton (an RGB-only
robot) has its camera read through the pose model (stream `POSE`). What is left is named in
one line with the option that maps it: nothing is dropped silently."""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from beyond_self.core.errors import InputError
from beyond_self.schemas import ros2 as r
from beyond_self.schemas.keys import DEFAULT_ROBOT

POSE = "pose"  # an image topic read through the pose model (person camera, skeleton, pose)
IMAGES = (r.IMAGE, r.COMPRESSED_IMAGE)
# role of `--topic ROLE=/name` -> the ROS 2 types it reads
ROLES: dict[str, tuple[str, ...]] = {
    "skeleton": (r.MARKER_ARRAY,),
    "tf": (r.TF_MESSAGE,),
    "camera": IMAGES,  # the tabletop camera the object segmenter reads
    "person_camera": IMAGES,  # a camera watching the person: through the pose model
}
# the Azure Kinect driver's colour topics, relative to its namespace
DRIVER_CAMERA = {"rgb/image_raw": r.IMAGE, "rgb/image_raw/compressed": r.COMPRESSED_IMAGE}
_COLOUR = re.compile(r"rgb|colou?r", re.IGNORECASE)
_NOT_COLOUR = re.compile(r"depth|(^|/)ir(/|$)|body_index|disparity|mask", re.IGNORECASE)


def parse_roles(items: Iterable[str]) -> dict[str, str]:
    """`--topic ROLE=/name` values -> role -> topic, refused on one line."""
    roles: dict[str, str] = {}
    for item in items:
        role, sep, topic = item.partition("=")
        if not sep or role not in ROLES:
            raise InputError(f"--topic {item!r}: expected ROLE=/topic; roles: {', '.join(ROLES)}")
        roles[role] = r.check_topic(topic if topic.startswith("/") else f"/{topic}")
    return roles


@dataclass
class Plan:
    """topic -> (robot, stream of ours or POSE) for what is read; `unread` for the rest."""

    routes: dict[str, tuple[str, str]] = field(default_factory=dict)
    unread: dict[str, str] = field(default_factory=dict)  # topic -> type

    def note(self) -> str:
        """The topics not read and how to read one ("" when every topic is read)."""
        if not self.unread:
            return ""
        listed = ", ".join(f"{t} ({ros_type})" for t, ros_type in sorted(self.unread.items()))
        example = next(
            (
                f"; e.g. --topic {role}={topic}"
                for topic, ros_type in sorted(self.unread.items())
                for role, types in ROLES.items()
                if ros_type in types
            ),
            "",
        )
        return (
            f"ROS 2 topics not read: {listed}; to read one, map it with --topic ROLE=/name "
            f"(roles: {', '.join(ROLES)}{example})"
        )


def _under(topic: str, relative: str) -> str | None:
    """The robot a topic `/<robot>/<relative>` (or `/<relative>`) is of, else None."""
    if topic != "/" + relative and not topic.endswith("/" + relative):
        return None
    robot = topic[: -len(relative) - 1].strip("/") or DEFAULT_ROBOT
    return None if "/" in robot else robot


def _image_stream(role: str, ros_type: str) -> str:
    if role == "person_camera":
        return "person_camera" if ros_type == r.COMPRESSED_IMAGE else POSE
    return "camera" if ros_type == r.IMAGE else "camera_compressed"


def plan(topics: Mapping[str, str], roles: Mapping[str, str] | None = None) -> Plan:
    """The plan for `topics` (topic -> ROS 2 type). `roles` (parse_roles) map topics by hand;
    a mapped topic must be there with a type its role reads."""
    out = Plan()
    roles = dict(roles or {})
    for role, topic in roles.items():
        ros_type = topics.get(topic)
        if ros_type is None:
            raise InputError(
                f"--topic {role}={topic}: no such topic; topics: {', '.join(sorted(topics))}"
            )
        if ros_type not in ROLES[role]:
            raise InputError(
                f"--topic {role}={topic}: a {ros_type}; valid: {' or '.join(ROLES[role])}"
            )
    mapped = {topic: role for role, topic in roles.items()}
    if not {"skeleton", "tf"} & set(roles):
        for topic, ros_type in topics.items():
            if topic == r.TF_TOPIC and ros_type == r.TF_MESSAGE:
                out.routes[topic] = (DEFAULT_ROBOT, "tf")
            elif ros_type == r.MARKER_ARRAY and (robot := _under(topic, "body_tracking_data")):
                out.routes[topic] = (robot, "skeleton")
    tabletop = _cameras(topics, out) if not {"camera", "person_camera"} & set(roles) else False
    robots = {robot for robot, _ in out.routes.values()}
    robot = robots.pop() if len(robots) == 1 else DEFAULT_ROBOT  # of a topic mapped by hand
    for topic, role in mapped.items():
        stream = role if role in ("skeleton", "tf") else _image_stream(role, topics[topic])
        out.routes[topic] = (DEFAULT_ROBOT if role == "tf" else robot, stream)
    _rgb_only(out, mapped, tabletop)
    for topic, ros_type in topics.items():
        ours = _under(topic, r.TOPICS["description"][0]) and ros_type == r.STRING
        if topic not in out.routes and not ours:
            out.unread[topic] = ros_type
    return out


def _rgb_only(out: Plan, mapped: Mapping[str, str], tabletop: bool) -> None:
    """Where body markers are read, `/tf` (which every ROS robot publishes) is not read as
    openni_tracker's too. A robot with a camera and no body markers is an RGB-only one: its
    camera (unless mapped by hand, or named as our tabletop camera beside a TF skeleton)
    watches the person, and `/tf` is not read either (a TF skeleton beside a camera is mapped
    with `--topic tf=/tf`)."""
    markers = {robot for robot, stream in out.routes.values() if stream == "skeleton"}
    markers |= {out.routes[topic][0] for topic, role in mapped.items() if role == "tf"}
    tf = {robot for robot, stream in out.routes.values() if stream == "tf"}
    if markers:  # body markers are the skeleton: a robot's /tf is not read as one too
        for topic, (_, stream) in list(out.routes.items()):
            if stream == "tf" and topic not in mapped:
                del out.routes[topic]
    cameras = ("camera", "camera_compressed", "person_camera")
    for topic, (robot, stream) in list(out.routes.items()):
        if robot in markers or stream not in cameras or topic in mapped:
            continue
        if tabletop and stream != "person_camera" and robot in tf:
            continue  # our tabletop camera beside openni_tracker's skeleton
        out.routes[topic] = (robot, POSE)
        for other, (_, kind) in list(out.routes.items()):
            if kind == "tf" and other not in mapped:
                del out.routes[other]


def _cameras(topics: Mapping[str, str], out: Plan) -> bool:
    """Cameras by name (ours, then the driver's), else one colour image topic by its type;
    True when ours named them."""
    found = False
    for topic, ros_type in topics.items():
        for stream in ("camera", "camera_compressed", "person_camera"):
            relative, typ = r.TOPICS[stream]
            if typ == ros_type and (robot := _under(topic, relative)):
                out.routes[topic] = (robot, stream)
                found = True
    if found:
        return True
    for relative, typ in DRIVER_CAMERA.items():  # the raw one first: one stream per camera
        for topic, ros_type in topics.items():
            robot = _under(topic, relative)
            if robot and ros_type == typ and not found:
                out.routes[topic] = (robot, _image_stream("camera", typ))
                found = True
    if found:
        return False
    images = sorted(t for t, typ in topics.items() if typ in IMAGES)
    colour = [t for t in images if _COLOUR.search(t)] or [
        t for t in images if not _NOT_COLOUR.search(t)
    ]
    raw = [t for t in colour if not any(t.startswith(o + "/") for o in colour)]
    if len(raw) == 1:  # one camera, maybe with its compressed topic: the raw one is read
        robots = {robot for robot, _ in out.routes.values()}
        robot = robots.pop() if len(robots) == 1 else DEFAULT_ROBOT
        out.routes[raw[0]] = (robot, _image_stream("camera", topics[raw[0]]))
    return False
