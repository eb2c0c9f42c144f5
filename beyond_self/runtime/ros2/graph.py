"""A node on the ROS 2 graph over the middleware chosen (runtime.ros2.rmw): rmw_zenoh's
(runtime.ros2.node) or DDS (runtime.ros2.dds), the same calls for the bridge and the live
source."""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from beyond_self.runtime.ros2 import rmw
from beyond_self.schemas import ros2 as r


class Publisher(Protocol):
    def put(self, cdr: bytes, stamp: int) -> None: ...


class Node(Protocol):
    name: str

    def publisher(self, topic: str, ros_type: str, qos: r.Qos) -> Publisher: ...

    def subscribe(
        self, topic: str, ros_type: str, qos: r.Qos, handler: Callable[[bytes], None]
    ) -> None: ...

    def close(self) -> None: ...


def open_node(name: str, namespace: str, *, middleware: str, connect: str, domain: int) -> Node:
    """Node `name` in `namespace` of ROS 2 domain `domain`: over DDS with the discovery
    ROS 2's variables ask for, or over rmw_zenoh through the router at `connect`."""
    if middleware == rmw.ZENOH:
        from beyond_self.runtime.ros2.node import Ros2Node

        return Ros2Node(name, namespace, connect=connect, domain=domain)
    from beyond_self.runtime.ros2.dds import DdsNode

    return DdsNode(name, namespace, domain=domain, config=rmw.cyclone_config())
