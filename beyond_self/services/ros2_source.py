"""A ROS 2 body tracker and camera as the pipeline's live source: the ingest's plug-in
(`beyond up --live-source beyond_self.services.ros2_source:source`) reads body markers (the
Azure Kinect driver's MarkerArray), openni_tracker's TF frames and cameras from a ROS 2 graph
(DDS or rmw_zenoh: runtime.ros2.rmw), and yields joints and RGB images with their own stamps.
Its settings are environment variables (a plug-in takes no arguments): ROS 2's own
(RMW_IMPLEMENTATION, ROS_DOMAIN_ID, discovery), BEYOND_ROS2_CONNECT (rmw_zenoh's router) and
the topics BEYOND_ROS2_SKELETON, BEYOND_ROS2_TF, BEYOND_ROS2_CAMERA (compressed),
BEYOND_ROS2_CAMERA_RAW and BEYOND_ROS2_PERSON_CAMERA ("" is not read). The person's camera goes
through the pose model as `up --camera` does (with no skeleton or TF topic, the camera is the
person's); samples convert as a bag's do (runtime.ros2.convert: the driver's axes into ours)."""

from __future__ import annotations

import asyncio
import logging
import os
from collections.abc import AsyncIterator, Callable
from typing import Any

from beyond_self.core.errors import InputError
from beyond_self.runtime.error_account import LogOnce
from beyond_self.runtime.recording.images import image_from_message
from beyond_self.runtime.ros2 import rmw
from beyond_self.runtime.ros2.convert import FromRos
from beyond_self.runtime.ros2.graph import open_node
from beyond_self.runtime.ros2.node import default_domain
from beyond_self.runtime.ros2.topics import POSE
from beyond_self.schemas import ros2 as r
from beyond_self.schemas.keys import DEFAULT_ROBOT
from beyond_self.schemas.messages import CameraFrame, CompressedCameraFrame, SkeletonFrame

log = logging.getLogger("beyond.ros2_source")
QUEUE = 64  # samples waiting for the ingest; beyond it the oldest is dropped
# environment variable -> (our input stream, ROS 2 type)
INPUTS = {
    "BEYOND_ROS2_SKELETON": ("skeleton", r.MARKER_ARRAY),
    "BEYOND_ROS2_TF": ("tf", r.TF_MESSAGE),
    "BEYOND_ROS2_CAMERA": ("camera_compressed", r.COMPRESSED_IMAGE),
    "BEYOND_ROS2_CAMERA_RAW": ("camera", r.IMAGE),
}
PERSON_CAMERA = "BEYOND_ROS2_PERSON_CAMERA"  # either image type: both are subscribed


def topics_from_env(robot: str) -> dict[str, tuple[str, str, str]]:
    """Topic -> (variable, stream, ROS 2 type) to read: each variable's topic, or the default
    of schemas.ros2 (`/<robot>/body_tracking_data`, `/tf`, `/<robot>/camera/image/compressed`;
    no raw camera unless named)."""
    defaults = r.Ros2Topics(robot)
    out: dict[str, tuple[str, str, str]] = {}
    for variable, (stream, ros_type) in INPUTS.items():
        fallback = "" if stream == "camera" else defaults.topic(stream)
        topic = os.environ.get(variable, fallback).strip()
        if topic:
            out[r.check_topic(topic)] = (variable, stream, ros_type)
    person = os.environ.get(PERSON_CAMERA, "").strip()
    if not any(stream in ("skeleton", "tf") for _, stream, _ in out.values()):
        # an RGB-only robot: its camera watches the person
        cameras = [t for t, (_, stream, _) in out.items() if stream.startswith("camera")]
        person = person or next(iter(cameras), "")
        for topic in cameras:
            del out[topic]
    if person:
        out[r.check_topic(person)] = (PERSON_CAMERA, POSE, "")
    return out


class PersonCamera:
    """A ROS 2 camera watching the person: each image through the pose model (made on first
    use, off the event loop), as services.pose_source does a camera's."""

    def __init__(self) -> None:
        self.estimator: Any = None
        self.index = 0

    async def item(self, image: tuple[int, Any]) -> tuple[str, Any, int]:
        from beyond_self.cognition.pose.estimator import PoseEstimator
        from beyond_self.runtime.recording.person import PersonFrame

        stamp, rgb = image
        if self.estimator is None:
            self.estimator = await asyncio.to_thread(PoseEstimator, video=True)
        pose = await asyncio.to_thread(self.estimator.estimate, rgb)
        self.index += 1
        return ("person", PersonFrame(self.index - 1, rgb, pose), stamp)

    def close(self) -> None:
        if self.estimator is not None:
            self.estimator.close()


def items_of(messages: list[Any]) -> list[tuple[str, Any, int]]:
    """The ingest's plug-in items (kind, payload, the message's own stamp) of our messages."""
    items: list[tuple[str, Any, int]] = []
    for m in messages:
        stamp = m.header.stamp
        if isinstance(m, SkeletonFrame):
            joints = {n: (*j.position, j.confidence) for n, j in m.joints.items()}
            items.append(("skeleton", joints, stamp))
        elif isinstance(m, CameraFrame | CompressedCameraFrame):
            items.append(("camera", image_from_message(m), stamp))
    return items


async def source() -> AsyncIterator[tuple[str, Any, int]]:
    """Items as they come from the ROS 2 graph, until cancelled; a sample that does not
    decode is logged (once per kind of problem) and skipped."""
    loop = asyncio.get_running_loop()
    queue: asyncio.Queue[tuple[str, str, bytes]] = asyncio.Queue(QUEUE)
    robot = os.environ.get("BEYOND_ROBOT", DEFAULT_ROBOT)
    node = open_node(
        f"beyond_{robot}_source",
        f"/{r.ros_name(robot)}",
        middleware=rmw.choose(),
        connect=os.environ.get("BEYOND_ROS2_CONNECT", r.DEFAULT_CONNECT),
        domain=default_domain(),
    )

    def enqueue(item: tuple[str, str, bytes]) -> None:
        if queue.full():
            queue.get_nowait()
        queue.put_nowait(item)

    def receiver(stream: str, ros_type: str) -> Callable[[bytes], None]:
        def receive(cdr: bytes) -> None:  # on the middleware's thread
            loop.call_soon_threadsafe(enqueue, (stream, ros_type, cdr))

        return receive

    person = PersonCamera()
    try:
        for topic, (_, stream, ros_type) in topics_from_env(robot).items():
            for typ in (ros_type,) if ros_type else (r.IMAGE, r.COMPRESSED_IMAGE):
                node.subscribe(topic, typ, r.SENSOR_QOS, receiver(stream, typ))
        convert = FromRos()
        once = LogOnce()
        while True:
            stream, ros_type, cdr = await queue.get()
            try:
                if stream == POSE:
                    yield await person.item(convert.image(ros_type, cdr))
                    continue
                converted = convert.convert(stream, ros_type, cdr)
            except InputError as exc:  # one bad sample is not the end of the source
                if once.first(stream, str(exc)):
                    log.warning("ROS 2 sample skipped: %s", exc)
                continue
            for item in items_of(converted):
                yield item
    finally:
        person.close()
        node.close()
