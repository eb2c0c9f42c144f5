"""A ROS 2 node on DDS, ROS 2's default middleware, with no ROS installed: one Cyclone DDS
participant whose topics are named and typed as rmw names them (`rt/<topic>`,
`<pkg>::msg::dds_::<Type>_`), with each topic's ROS 2 QoS, the type hash in each endpoint's
user data (`typehash=RIHS01_...;`) and the node and its endpoints' GIDs on
`ros_discovery_info`, as rmw does since Iron. Samples are rosbags' CDR bytes, written and
taken as they are (runtime.ros2.idl makes the topic types)."""

from __future__ import annotations

import ctypes as ct
import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from cyclonedds._clayer import ddspy_take, ddspy_write_ts
from cyclonedds.core import DDSException, InstanceState, Listener, SampleState, ViewState
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.internal import load_cyclonedds
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from beyond_self.runtime.log import event
from beyond_self.runtime.ros2.convert import serialize, store, type_hash
from beyond_self.runtime.ros2.idl import topic_type
from beyond_self.schemas import ros2 as r

log = logging.getLogger("beyond.ros2")
DISCOVERY_TOPIC = "ros_discovery_info"
PARTICIPANT_INFO = "rmw_dds_common/msg/ParticipantEntitiesInfo"
ANY = SampleState.Any | ViewState.Any | InstanceState.Any
TAKE = 64  # samples taken per call
SERTYPE_WORDS = 64  # how far into the binding's sertype its Python type is looked for
LINGER = duration(seconds=2)  # the longest close waits for acknowledgements


def topic_name(topic: str) -> str:
    """rmw's DDS topic of a ROS 2 topic: `/robot/description` -> `rt/robot/description`."""
    return "rt/" + r.check_topic(topic).strip("/")


def dds_qos(qos: r.Qos, ros_type: str | None) -> Qos:
    """A ROS 2 QoS profile as rmw sets it on a DDS endpoint: reliability, durability, keep-last
    depth, XCDR1 (ROS 2's CDR), and the type hash in the endpoint's user data."""
    policies: list[Any] = [
        Policy.Reliability.Reliable(duration(milliseconds=100))
        if qos.reliable
        else Policy.Reliability.BestEffort,
        Policy.Durability.TransientLocal if qos.transient_local else Policy.Durability.Volatile,
        Policy.History.KeepLast(qos.depth),
        Policy.DataRepresentation(use_cdrv0_representation=True),
    ]
    if ros_type is not None:
        policies.append(Policy.Userdata(f"typehash={type_hash(ros_type)};".encode()))
    return Qos(*policies)


def padded(cdr: bytes) -> bytes:
    """CDR padded to 4 bytes, the padding counted in the encapsulation options (XTypes 7.6.3)."""
    pad = -len(cdr) % 4
    if not pad:
        return cdr
    return cdr[:3] + bytes([cdr[3] | pad]) + cdr[4:] + b"\0" * pad


def unpadded(cdr: bytes) -> bytes:
    """CDR without the padding its encapsulation options count (nor the count)."""
    pad = cdr[3] & 3 if len(cdr) >= 4 else 0
    return cdr[:3] + bytes([cdr[3] & ~3]) + cdr[4 : len(cdr) - pad] if pad else cdr


def matched_by_name(topic: Topic[Any], cls: type[Any]) -> bool:
    """Make the endpoints created on `topic` from now on announce no XTypes type information,
    so that they match by type name, as rmw_cyclonedds's and rmw_fastrtps's own do with each
    other. Cyclone rejects the type objects Fast DDS announces for types with a sequence (an
    element identifier it reads as invalid), and then never matches them; the binding insists
    on type information for a topic. Done on the binding's sertype in memory, after checking
    that it is laid out as expected (cyclonedds-python 11: the Python type, four flags, then the
    serialized type information and its size); False when it is not, and nothing changed."""
    sertype = ct.c_void_p()
    get = load_cyclonedds().dds_get_entity_sertype
    get.argtypes, get.restype = [ct.c_int32, ct.POINTER(ct.c_void_p)], ct.c_int32
    if get(topic._ref, ct.byref(sertype)) != 0 or not sertype.value:
        return False
    info = cls.__idl__._xt_bytedata[0]
    words = (ct.c_uint64 * SERTYPE_WORDS).from_address(sertype.value)
    try:
        offset = 8 * next(i for i in range(SERTYPE_WORDS) if words[i] == id(cls))
    except StopIteration:
        return False
    data = ct.c_void_p.from_address(sertype.value + offset + 16)
    size = ct.c_uint32.from_address(sertype.value + offset + 24)
    if size.value != len(info) or not data.value or ct.string_at(data.value, size.value) != info:
        return False
    size.value = 0  # the binding's type_info/type_id now find none; the buffer is freed as ever
    return True


@dataclass
class DdsPublisher:
    """One ROS 2 publisher: CDR in, one DDS sample out, its source timestamp the stamp."""

    writer: DataWriter[Any]
    gid: bytes

    def put(self, cdr: bytes, stamp: int) -> None:
        status = ddspy_write_ts(self.writer._ref, padded(cdr), stamp)
        if status < 0:
            raise DDSException(status, f"writing a sample on {self.writer.topic.name}")


class DdsNode:
    """A node `name` in namespace `namespace` of ROS 2 domain `domain` over DDS; `config` is
    Cyclone's configuration (runtime.ros2.rmw.cyclone_config), None for Cyclone's own."""

    def __init__(self, name: str, namespace: str, *, domain: int, config: str | None) -> None:
        self.name, self.namespace, self.domain = r.ros_name(name), namespace, domain
        self._domain = Domain(domain, config) if config is not None else None
        self.participant = DomainParticipant(domain, qos=Qos(Policy.Userdata(b"enclave=/;")))
        self._topics: dict[tuple[str, str], Topic[Any]] = {}  # (DDS topic, ROS 2 type)
        self._readers: list[DataReader[Any]] = []
        self._listeners: list[Listener] = []  # kept alive as long as their readers
        self._writers: list[DataWriter[Any]] = []
        self._gids: dict[str, list[bytes]] = {"reader": [], "writer": []}
        self._lock = threading.Lock()
        info = self._typed_topic(DISCOVERY_TOPIC, PARTICIPANT_INFO)
        discovery = r.Qos(reliable=True, transient_local=True, depth=1)
        self._info = DataWriter(self.participant, info, dds_qos(discovery, None))
        self._announce()

    def _topic(self, topic: str, ros_type: str) -> Topic[Any]:
        return self._typed_topic(topic_name(topic), ros_type)

    def _typed_topic(self, name: str, ros_type: str) -> Topic[Any]:
        found = self._topics.get((name, ros_type))
        if found is None:
            cls = topic_type(ros_type)
            found = self._topics[name, ros_type] = Topic(self.participant, name, cls)
            if not matched_by_name(found, cls):
                event(log, logging.WARNING, "DDS type information left on", topic=name)
        return found

    def _announce(self) -> None:
        """This participant's nodes and their endpoints' GIDs on ros_discovery_info."""
        t = store().types

        def gid(raw: bytes) -> Any:
            return t["rmw_dds_common/msg/Gid"](data=np.frombuffer(raw, np.uint8))

        node = t["rmw_dds_common/msg/NodeEntitiesInfo"](
            node_namespace=self.namespace, node_name=self.name,
            reader_gid_seq=[gid(g) for g in self._gids["reader"]],
            writer_gid_seq=[gid(g) for g in self._gids["writer"]],
        )  # fmt: skip
        info = t[PARTICIPANT_INFO](
            gid=gid(self.participant.guid.bytes), node_entities_info_seq=[node]
        )
        self._write(self._info, serialize(PARTICIPANT_INFO, info))

    @staticmethod
    def _write(writer: DataWriter[Any], cdr: bytes) -> None:
        from time import time_ns

        ddspy_write_ts(writer._ref, padded(cdr), time_ns())

    def publisher(self, topic: str, ros_type: str, qos: r.Qos) -> DdsPublisher:
        writer = DataWriter(self.participant, self._topic(topic, ros_type), dds_qos(qos, ros_type))
        self._writers.append(writer)
        gid = writer.guid.bytes
        self._gids["writer"].append(gid)
        self._announce()
        return DdsPublisher(writer, gid)

    def subscribe(
        self, topic: str, ros_type: str, qos: r.Qos, handler: Callable[[bytes], None]
    ) -> None:
        """`handler(cdr)` for every sample on the topic (on Cyclone's thread)."""

        def on_data_available(reader: DataReader[Any]) -> None:
            with self._lock:
                taken = ddspy_take(reader._ref, ANY, TAKE)
            if isinstance(taken, int):
                return
            for data, info in taken:
                if info.valid_data:
                    handler(unpadded(bytes(data)))

        def on_subscription_matched(reader: DataReader[Any], status: Any) -> None:
            event(log, logging.INFO, "ROS 2 publishers matched", topic=topic,
                  publishers=int(status.current_count))  # fmt: skip

        listener = Listener(  # type: ignore[no-untyped-call]
            on_data_available=on_data_available, on_subscription_matched=on_subscription_matched
        )
        reader = DataReader(
            self.participant, self._topic(topic, ros_type), dds_qos(qos, ros_type),
            listener=listener,
        )  # fmt: skip
        self._readers.append(reader)
        self._listeners.append(listener)
        self._gids["reader"].append(reader.guid.bytes)
        self._announce()

    def close(self) -> None:
        """Leave the graph once every matched reliable reader has acknowledged what was
        written (a sentence said just before the end still arrives), at most LINGER."""
        for writer in self._writers:
            writer.wait_for_acks(LINGER)
        self._readers.clear()
        self._listeners.clear()
        self._writers.clear()
        self._topics.clear()
        self.participant.__del__()
        if self._domain is not None:
            self._domain.__del__()
