"""rosbag2 bags as recordings: a bag folder (metadata.yaml + MCAP storage) names its MCAP file,
whose CDR channels in schemas.ros2's conventions the recording reader (runtime.recording.reader)
turns into our messages as it reads (`Ros2Channels`). The MCAP walk, and so the damaged-file
policy, is the one of our own recordings; writing a bag is runtime.ros2.bag_export."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from mcap.records import Channel, Schema
from mcap.records import Message as McapMessage

from beyond_self.core.errors import InputError
from beyond_self.runtime.recording.format import JSON, META_FORM, META_TYPE
from beyond_self.schemas.base import Message
from beyond_self.schemas.codec import RECORDING_JSON_FORM, to_recording_json
from beyond_self.schemas.keys import DEFAULT_ROBOT, Keys, type_for_key

CDR = "cdr"
ROS2_SCHEMAS = ("ros2msg", "ros2idl")
METADATA = "metadata.yaml"
Pair = tuple[Channel, McapMessage]


def bag_file(path: Path) -> Path:
    """The MCAP file of a rosbag2 bag folder (`path` itself when it is no folder)."""
    if not path.is_dir():
        return path
    meta = path / METADATA
    if not meta.is_file():
        raise InputError(f"recording {path} is a folder without {METADATA}; valid: an MCAP "
                         "file or a rosbag2 bag folder")  # fmt: skip
    try:
        info = yaml.safe_load(meta.read_text())["rosbag2_bagfile_information"]
        storage, files = info["storage_identifier"], info["relative_file_paths"]
    except (yaml.YAMLError, KeyError, TypeError):
        raise InputError(f"{meta} is not rosbag2 metadata") from None
    if storage != "mcap":
        raise InputError(f"bag {path} is stored in {storage!r}; valid: a bag in MCAP storage")
    if len(files) != 1:
        raise InputError(f"bag {path} has {len(files)} storage files; valid: one")
    return path / str(files[0])


def ros_stream(topic: str, ros_type: str) -> tuple[str, str] | None:
    """(robot, input stream) a ROS 2 topic of `ros_type` feeds by the default topic names
    (schemas.ros2.TOPICS, `/tf`), else None (a description is an output: never read)."""
    from beyond_self.schemas import ros2 as r

    if topic == r.TF_TOPIC and ros_type == r.TF_MESSAGE:
        return DEFAULT_ROBOT, "tf"
    for stream, (relative, typ) in r.TOPICS.items():
        if typ != ros_type or stream == "description" or not topic.endswith("/" + relative):
            continue
        robot = topic[: -len(relative) - 1].strip("/") or DEFAULT_ROBOT
        if "/" not in robot:
            return robot, stream
    return None


ROS2_CHANNELS = 1 << 16  # ids of the channels a bag is read into (MCAP's are 16-bit)


@dataclass
class Ros2Channels:
    """A ROS 2 bag's channels as channels of ours, for the recording reader: each CDR sample
    becomes the messages of ours it holds (runtime.ros2.convert), on our key, as recording
    JSON, so every command reads a bag as it reads our own recordings."""

    converter: Any = None
    routes: dict[int, tuple[str, str, str]] = field(default_factory=dict)  # id -> key,stream,type
    ours: dict[str, Channel] = field(default_factory=dict)  # key -> the channel read into

    def route(self, channel: Channel, schema: Schema | None) -> str | None:
        """For a ROS 2 channel (CDR, ros2msg/ros2idl schema) our key ("": one not read),
        None for any other channel."""
        if channel.message_encoding != CDR or schema is None or schema.encoding not in ROS2_SCHEMAS:
            return None
        found = ros_stream(channel.topic, schema.name)
        if found is None:
            return ""
        robot, stream = found
        from beyond_self.runtime.ros2.convert import FromRos, stream_of_ros

        if self.converter is None:
            self.converter = FromRos()
        key = Keys(robot).stream(stream_of_ros(stream))
        self.routes[channel.id] = (key, stream, schema.name)
        return key

    def _channel(self, key: str) -> Channel:
        """The channel of ours `key` is read into (made on first use)."""
        found = self.ours.get(key)
        if found is None:
            cls = type_for_key(key)
            assert cls is not None  # ros_stream routes to sensor streams of ours only
            meta = {META_TYPE: cls.type_name(), META_FORM: str(RECORDING_JSON_FORM)}
            cid = ROS2_CHANNELS + len(self.ours)
            found = self.ours[key] = Channel(
                id=cid, schema_id=0, topic=key, message_encoding=JSON, metadata=meta
            )
        return found

    def _pairs(self, key: str, messages: list[Message], log_time: int | None) -> list[Pair]:
        channel = self._channel(key)
        return [
            (channel, McapMessage(
                channel_id=channel.id, log_time=m.header.stamp if log_time is None else log_time,
                data=to_recording_json(m), publish_time=m.header.stamp, sequence=0,
            ))
            for m in messages
        ]  # fmt: skip

    def convert(self, record: McapMessage) -> list[Pair]:
        """Our messages in one sample, on our channels; InputError if it does not convert."""
        key, stream, ros_type = self.routes[record.channel_id]
        return self._pairs(
            key, self.converter.convert(stream, ros_type, record.data), record.log_time
        )

    def flush(self) -> list[Pair]:
        """The skeleton frame TF samples left open at the end of the bag, if any."""
        if self.converter is None:
            return []
        keys = {stream: key for key, stream, _ in self.routes.values()}
        return self._pairs(keys.get("tf", Keys().skeleton), self.converter.flush(), None)
