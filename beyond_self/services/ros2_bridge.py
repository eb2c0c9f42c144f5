"""The deployment's face on a ROS 2 graph (DDS or rmw_zenoh, runtime.ros2.rmw): each final
description's best sentence as std_msgs/String on /<robot>/description, the skeleton as the
Azure Kinect driver's body markers and the cameras as image_transport's CompressedImage, each
stamped with its own message's stamp (schemas.ros2 names topics and types, runtime.ros2.convert
converts, runtime.ros2.graph opens the node).

A sentence is said once, across a SIGKILL, as the speech service says it (services.speech): a
consumer in exactly-once whose `once=` is its own log, written before the sentence is
published and read back by a restarted bridge. A kill between the two loses that sentence
rather than saying it twice; the log is not synced, so a power loss may let one be said again."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from beyond_self.runtime.bus.delivery import CAMERA, EVENTS, SKELETON
from beyond_self.runtime.log import event
from beyond_self.runtime.outputs import service_out_dir
from beyond_self.runtime.resilience.effect_log import EffectLog
from beyond_self.runtime.ros2 import rmw
from beyond_self.runtime.ros2.convert import to_ros
from beyond_self.runtime.ros2.graph import Node, Publisher, open_node
from beyond_self.runtime.ros2.node import DEFAULT_CONNECT, default_domain, domain
from beyond_self.runtime.service import Service
from beyond_self.schemas import ros2 as r
from beyond_self.schemas.base import Message
from beyond_self.schemas.messages import (
    CameraFrame,
    CompressedCameraFrame,
    Description,
    SkeletonFrame,
)

# our stream -> (message type, delivery) the bridge takes it with
OUT: dict[str, tuple[type[Message], Any]] = {
    "skeleton": (SkeletonFrame, SKELETON),
    "camera": (CameraFrame, CAMERA),
    "camera_compressed": (CompressedCameraFrame, CAMERA),
    "person_camera": (CompressedCameraFrame, CAMERA),
}


class Ros2Bridge(Service):
    name = "ros2"
    subscribes = ("description", *OUT)
    publishes = ()
    serves = ()

    def __init__(
        self,
        *,
        connect: str = DEFAULT_CONNECT,
        domain_id: int | str | None = None,
        out_dir: str | None = None,
        topics: dict[str, str] | None = None,
        middleware: str | None = None,
        **base: Any,
    ) -> None:
        super().__init__(**base)
        self.middleware = rmw.choose(middleware)
        self.connect = connect
        self.domain = default_domain() if domain_id is None else domain(domain_id)
        self.out_dir = Path(out_dir) if out_dir is not None else service_out_dir("ros2")
        self.renamed = dict(topics or {})
        self.node: Node | None = None
        self.out: dict[str, Publisher] = {}
        # written before each sentence is published, not synced: a kill cannot lose a write
        # already made, and a synced one took milliseconds a description should not wait
        self.said = EffectLog(self.out_dir / "said.log", sync=False)
        self.published = 0

    async def setup(self) -> None:
        keys = self.bus.keys
        topics = r.Ros2Topics(keys.robot, self.renamed)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        node = self.node = open_node(
            f"beyond_{keys.robot}", f"/{r.ros_name(keys.robot)}", middleware=self.middleware,
            connect=self.connect, domain=self.domain,
        )  # fmt: skip
        for stream, (relative, ros_type) in r.TOPICS.items():
            del relative
            qos = r.RELIABLE_QOS if stream == "description" else r.SENSOR_QOS
            self.out[stream] = node.publisher(topics.topic(stream), ros_type, qos)
        self.subscribe(keys.description, Description, self.on_description, EVENTS, once=self.said)
        for stream, (cls, delivery) in OUT.items():
            self.subscribe(keys.stream(stream), cls, self._forward(stream), delivery)
        event(self.log, logging.INFO, "on the ROS 2 graph", middleware=self.middleware,
              connect=self.connect, domain=self.domain, node=node.name)  # fmt: skip

    def _forward(self, stream: str) -> Any:
        def forward(message: Message) -> None:
            converted = to_ros(stream, message)
            if converted is not None:
                self.out[stream].put(converted[1], message.header.stamp)
                self.published += 1

        return forward

    def on_description(self, msg: Description) -> None:
        if not msg.final or not msg.sentences:
            return
        converted = to_ros("description", msg)
        assert converted is not None  # a description with a sentence has one
        text = msg.sentences[0].text
        self.said.append(msg.header.stamp, msg.segment_id, "-", text)  # the commit
        self.out["description"].put(converted[1], msg.header.stamp)
        self.published += 1

    async def teardown(self) -> None:
        if self.node is not None:
            self.node.close()
            self.node = None
