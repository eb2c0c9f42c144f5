"""A recording of ours as a rosbag2 bag `ros2 bag play` could play (`export`, `beyond ros2
export`): each stream with a standard ROS type on its topic, written with rosbags' writer in MCAP
storage, its channels described as rosbag2's own MCAP plugin describes them."""

from __future__ import annotations

from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import Any

from beyond_self.core.errors import InputError
from beyond_self.runtime.recording.reader import read_recording
from beyond_self.runtime.ros2.convert import store, to_ros
from beyond_self.schemas import ros2 as r
from beyond_self.schemas.keys import STREAMS, split_key


def _writer_class() -> Any:
    """rosbags' rosbag2 writer whose MCAP channels carry `topic_type_hash` beside
    `offered_qos_profiles`, as rosbag2's own MCAP plugin writes them (rosbags writes the hash
    in metadata.yaml only)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2 import storage_mcap as sm

    class HashedMcapWriter(sm.McapWriter):
        def add_connection(self, connection: Any, offered_qos_profiles: str) -> None:
            metadata = BytesIO()
            for key, value in (
                ("offered_qos_profiles", offered_qos_profiles),
                ("topic_type_hash", connection.digest),
            ):
                sm.write_string(metadata, key)
                sm.write_string(metadata, value)
            self.channels.append(
                sm.Channel(connection.id, connection.msgtype, connection.topic,
                           connection.ext.serialization_format, metadata.getvalue())
            )  # fmt: skip
            self.channel_stats[connection.id] = 0
            sm.write_channel(self.chunk.bio, self.channels[-1], self.schemas)

    class BagWriter(Writer):
        STORAGE_PLUGINS = {  # noqa: RUF012  # rosbags declares it so
            **Writer.STORAGE_PLUGINS,
            StoragePlugin.MCAP: HashedMcapWriter,
        }

    return BagWriter, StoragePlugin.MCAP


@dataclass
class ExportStats:
    messages: int = 0
    skipped: dict[str, int] = field(default_factory=dict)  # key -> messages without a ROS type


def export(source: Path, target: Path, *, robot: str | None = None) -> ExportStats:
    """Write recording `source` as rosbag2 bag folder `target` (which must not exist): each
    stream with a standard type (schemas.ros2) on its topic under `/<robot>`, stamped with the
    message's own stamp; what has none is counted in `skipped`."""
    from rosbags.interfaces import (
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )
    from rosbags.rosbag2 import CompressionFormat, CompressionMode

    if target.is_dir() and not any(target.iterdir()):
        target.rmdir()  # an empty folder (`-o` makes it): rosbags' writer makes its own
    if target.exists():
        raise InputError(f"{target} exists; valid: a new or empty folder for the bag")
    suffixes = {suffix: name for name, (suffix, _) in STREAMS.items()}
    stats = ExportStats()
    writer_class, plugin = _writer_class()
    forever = QosTime(2147483647, 4294967295)
    writer = writer_class(target, version=9, storage_plugin=plugin)
    writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)  # chunks, as ours
    connections: dict[str, Any] = {}
    with writer:
        for item in read_recording(source):
            split = split_key(item.key)
            stream = suffixes.get(split[1]) if split else None
            if item.cls is None or split is None or stream not in r.TOPICS:
                stats.skipped[item.key] = stats.skipped.get(item.key, 0) + 1
                continue
            converted = to_ros(stream, item.message())
            if converted is None:
                stats.skipped[item.key] = stats.skipped.get(item.key, 0) + 1
                continue
            ros_type, cdr = converted
            topic = r.Ros2Topics(robot or split[0]).topic(stream)
            connection = connections.get(topic)
            if connection is None:
                qos = r.RELIABLE_QOS if stream == "description" else r.SENSOR_QOS
                connection = connections[topic] = writer.add_connection(
                    topic,
                    ros_type,
                    typestore=store(),
                    offered_qos_profiles=[
                        Qos(QosHistory.KEEP_LAST, qos.depth,
                            QosReliability.RELIABLE if qos.reliable else QosReliability.BEST_EFFORT,
                            QosDurability.VOLATILE, forever, forever, QosLiveliness.AUTOMATIC,
                            forever, False)
                    ],
                )  # fmt: skip
            writer.write(connection, item.publish_time, cdr)
            stats.messages += 1
    return stats
