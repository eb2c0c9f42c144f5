"""A ROS 2 node on rmw_zenoh's network, with no ROS installed: its own Zenoh session (a peer of
the ROS 2 router, apart from our bus), liveliness tokens for the node and each publisher and
subscription (schemas.ros2's keys, so `ros2 node list` and `ros2 topic list -t` see them), and
samples with rmw_zenoh's attachment: sequence number, source timestamp and publisher GID, as
zenoh-ext's serializer writes them (8 + 8 + 1 + 16 bytes, ros2/rmw_zenoh docs/design.md)."""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import zenoh
import zenoh.ext

from beyond_self.core.errors import InputError
from beyond_self.runtime.ros2.convert import type_hash
from beyond_self.schemas import ros2 as r

DEFAULT_CONNECT = r.DEFAULT_CONNECT


def default_domain() -> int:
    """$ROS_DOMAIN_ID, or 0."""
    text = os.environ.get("ROS_DOMAIN_ID", "").strip() or "0"
    return domain(text)


def domain(text: str | int) -> int:
    value = int(text) if str(text).isdigit() else -1
    if not 0 <= value <= 232:
        raise InputError(f"ROS 2 domain {text!r}; valid: 0..232")
    return value


def attachment(seq: int, stamp: int, gid: bytes) -> bytes:
    """rmw_zenoh's per-sample attachment (its AttachmentData, zenoh-ext serialized)."""
    payload = zenoh.ext.z_serialize((zenoh.ext.Int64(seq), zenoh.ext.Int64(stamp), gid))
    return payload.to_bytes()


def read_attachment(data: bytes) -> tuple[int, int, bytes]:
    """(sequence number, source timestamp, GID) of an attachment."""
    seq, stamp, gid = zenoh.ext.z_deserialize(
        tuple[zenoh.ext.Int64, zenoh.ext.Int64, bytes], zenoh.ZBytes(data)
    )
    return int(seq), int(stamp), gid


@dataclass
class Ros2Publisher:
    """One ROS 2 publisher: CDR in, a sample on its data key with the attachment out."""

    publisher: zenoh.Publisher
    token: zenoh.LivelinessToken
    key: str
    gid: bytes
    seq: int = 0

    def put(self, cdr: bytes, stamp: int) -> None:
        """Publish one message; its source timestamp is the message's own stamp."""
        self.seq += 1
        self.publisher.put(cdr, attachment=attachment(self.seq, stamp, self.gid))


class Ros2Node:
    """A node `name` in namespace `namespace` of ROS 2 domain `domain`, reached through
    `connect` (rmw_zenoh's router). Blocking calls; a service runs its handlers on its loop."""

    def __init__(self, name: str, namespace: str, *, connect: str, domain: int) -> None:
        config = zenoh.Config()
        config.insert_json5("mode", json.dumps("peer"))
        config.insert_json5("connect/endpoints", json.dumps([connect]))
        config.insert_json5("listen/endpoints", json.dumps(["tcp/127.0.0.1:0"]))
        config.insert_json5("scouting/multicast/enabled", "false")
        self.session = zenoh.open(config)
        self.domain, self.name, self.namespace = domain, r.ros_name(name), namespace
        self.zid = str(self.session.info.zid())
        self._entities = 0
        self._tokens: list[zenoh.LivelinessToken] = []
        self._closers: list[Callable[[], None]] = []
        node = r.node_token(domain, self.zid, 0, namespace, self.name)
        self._tokens.append(self.session.liveliness().declare_token(node))

    def _endpoint(self, kind: str, topic: str, ros_type: str, qos: r.Qos) -> str:
        self._entities += 1
        return r.endpoint_token(
            kind, self.domain, self.zid, 0, self._entities, self.namespace, self.name,
            topic, ros_type, type_hash(ros_type), qos,
        )  # fmt: skip

    def publisher(self, topic: str, ros_type: str, qos: r.Qos) -> Ros2Publisher:
        r.check_topic(topic)
        key = r.data_key(self.domain, topic, ros_type, type_hash(ros_type))
        token_key = self._endpoint(r.PUBLISHER, topic, ros_type, qos)
        pub = self.session.declare_publisher(
            key,
            encoding=zenoh.Encoding.ZENOH_BYTES,
            reliability=zenoh.Reliability.RELIABLE
            if qos.reliable
            else zenoh.Reliability.BEST_EFFORT,
            # rmw_zenoh blocks only a reliable keep-all publisher; a sentence is not dropped
            congestion_control=zenoh.CongestionControl.BLOCK
            if qos.reliable
            else zenoh.CongestionControl.DROP,
        )
        token = self.session.liveliness().declare_token(token_key)
        self._closers.append(pub.undeclare)
        self._tokens.append(token)
        return Ros2Publisher(pub, token, key, r.gid(token_key))

    def subscribe(
        self, topic: str, ros_type: str, qos: r.Qos, handler: Callable[[bytes], None]
    ) -> None:
        """`handler(cdr)` for every sample on the topic (on Zenoh's thread)."""
        r.check_topic(topic)
        key = r.data_key(self.domain, topic, ros_type, type_hash(ros_type))

        def on_sample(sample: Any) -> None:
            handler(sample.payload.to_bytes())

        sub = self.session.declare_subscriber(key, on_sample)
        self._closers.append(sub.undeclare)
        token = self._endpoint(r.SUBSCRIPTION, topic, ros_type, qos)
        self._tokens.append(self.session.liveliness().declare_token(token))

    def close(self) -> None:
        for close in self._closers:
            close()
        for token in self._tokens:
            token.undeclare()  # type: ignore[no-untyped-call]  # zenoh stub lacks "-> None"
        self._closers.clear()
        self._tokens.clear()
        self.session.close()  # type: ignore[no-untyped-call]  # zenoh stub lacks "-> None"
