"""rosbag2 bags as recordings: the recording reader (runtime.recording.reader) reads a bag in
MCAP storage in one uncompressed file with our own MCAP walk, and so with the damaged-file
policy of our recordings, and any other (sqlite3, split over files, zstd per file or message)
through rosbags' reader (`rosbag_records`); either way its CDR topics, planned over the whole
bag (runtime.ros2.topics), become our messages as they are read (`Ros2Channels`). Writing a
bag is runtime.ros2.bag_export."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from mcap.records import Channel, Schema
from mcap.records import Message as McapMessage

from beyond_self.core.errors import InputError
from beyond_self.runtime.recording.format import JSON, META_FORM, META_TYPE
from beyond_self.runtime.ros2.topics import POSE, Plan, plan
from beyond_self.schemas.base import Message
from beyond_self.schemas.codec import RECORDING_JSON_FORM, to_recording_json
from beyond_self.schemas.keys import DEFAULT_ROBOT, Keys, type_for_key

CDR = "cdr"
ROS2_SCHEMAS = ("ros2msg", "ros2idl")
METADATA = "metadata.yaml"
Pair = tuple[Channel, McapMessage]


STORAGES = ("mcap", "sqlite3")  # rosbag2's storage plugins (sqlite3: Humble's default)


def bag_file(path: Path) -> Path:
    """What the recording reader reads of `path`: the MCAP file of a rosbag2 bag folder that
    our MCAP walk reads as it is (MCAP storage, one file, no compression of files or messages),
    so a damaged one is read up to its damage as our recordings are; the folder itself for one
    rosbags reads (`rosbag_records`: sqlite3, split over files, zstd-compressed); `path`
    itself when it is no folder."""
    if not path.is_dir():
        return path
    meta = path / METADATA
    if not meta.is_file():
        raise InputError(f"recording {path} is a folder without {METADATA}; valid: an MCAP "
                         "file or a rosbag2 bag folder")  # fmt: skip
    try:
        info = yaml.safe_load(meta.read_text())["rosbag2_bagfile_information"]
        storage, files = info["storage_identifier"], info["relative_file_paths"]
        compression = str(info.get("compression_mode") or "").lower()
    except (yaml.YAMLError, KeyError, TypeError, AttributeError):
        raise InputError(f"{meta} is not rosbag2 metadata") from None
    if storage not in STORAGES:
        raise InputError(f"bag {path} is stored in {storage!r}; valid: {', '.join(STORAGES)}")
    if storage == "mcap" and len(files) == 1 and compression in ("", "none"):
        return path / str(files[0])
    return path


def rosbag_records(path: Path) -> Iterator[Schema | Channel | McapMessage]:
    """A bag folder rosbags reads, as the MCAP records our reader handles: a schema and a
    channel for each topic, then its messages in storage order (rosbags decompresses files and
    messages). A bag rosbags cannot read is refused on one line."""
    import sqlite3

    from rosbags.rosbag2 import Reader
    from rosbags.rosbag2.errors import ReaderError

    try:
        with Reader(path) as reader:
            for c in reader.connections:
                yield Schema(id=c.id, name=c.msgtype, encoding=ROS2_SCHEMAS[0], data=b"")
                yield Channel(id=c.id, schema_id=c.id, topic=c.topic, message_encoding=CDR,
                              metadata={})  # fmt: skip
            for c, stamp, data in reader.messages():
                yield McapMessage(channel_id=c.id, sequence=0, log_time=stamp,
                                  publish_time=stamp, data=bytes(data))  # fmt: skip
    except (ReaderError, sqlite3.Error, OSError, ValueError) as exc:
        raise InputError(f"bag {path} does not read: {exc}") from None


def bag_size(path: Path) -> int:
    """The bytes of a bag folder's files."""
    return sum(f.stat().st_size for f in path.iterdir() if f.is_file())


ROS2_CHANNELS = 1 << 16  # ids of the channels a bag is read into (MCAP's are 16-bit)


@dataclass
class Ros2Channels:
    """A ROS 2 bag's channels as channels of ours, for the recording reader: which topic feeds
    which stream is planned over all the bag's topics (runtime.ros2.topics, with the user's
    `roles`), and each CDR sample becomes the messages of ours it holds (runtime.ros2.convert;
    an RGB-only robot's camera through the pose model, runtime.ros2.person), on our key, as
    recording JSON, so every command reads a bag as it reads our own recordings."""

    roles: Mapping[str, str] = field(default_factory=dict)
    converter: Any = None
    person: Any = None  # the pose model's reader of an RGB-only robot's camera (made on use)
    topics: dict[str, str] = field(default_factory=dict)  # every ROS 2 topic met -> type
    planned: Plan | None = None  # over `topics` (None: a topic was met since)
    routes: dict[int, tuple[str, str]] = field(default_factory=dict)  # channel id -> topic, type
    ours: dict[str, Channel] = field(default_factory=dict)  # key -> the channel read into

    @property
    def plan(self) -> Plan:
        """The plan over every topic met so far, made when a sample needs it: all of a bag's
        topics are met before its first sample (summary, metadata, or a file's first chunk)."""
        if self.planned is None:
            self.planned = plan(self.topics, self.roles)
        return self.planned

    def route(self, channel: Channel, schema: Schema | None) -> bool:
        """Whether `channel` is a ROS 2 one (CDR, ros2msg/ros2idl schema), read here or
        named in `note()`; False for any other channel."""
        if channel.message_encoding != CDR or schema is None or schema.encoding not in ROS2_SCHEMAS:
            return False
        if self.topics.get(channel.topic) != schema.name:
            self.topics[channel.topic] = schema.name
            self.planned = None
        self.routes[channel.id] = (channel.topic, schema.name)
        return True

    def note(self) -> str:
        return self.plan.note()

    def _channel(self, key: str) -> Channel:
        """The channel of ours `key` is read into (made on first use)."""
        found = self.ours.get(key)
        if found is None:
            cls = type_for_key(key)
            assert cls is not None  # topics.plan routes to sensor streams of ours only
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
        """Our messages in one sample, on our channels (none for a topic not read);
        InputError if it does not convert."""
        from beyond_self.runtime.ros2.convert import FromRos, stream_of_ros

        topic, ros_type = self.routes[record.channel_id]
        found = self.plan.routes.get(topic)
        if found is None:
            return []
        robot, stream = found
        if self.converter is None:
            self.converter = FromRos()
        if stream == POSE:
            if self.person is None:
                from beyond_self.runtime.ros2.person import PersonCamera

                self.person = PersonCamera()
            image = self.converter.image(ros_type, record.data)
            return [
                pair
                for name, message in self.person.messages(image)
                for pair in self._pairs(Keys(robot).stream(name), [message], record.log_time)
            ]
        key = Keys(robot).stream(stream_of_ros(stream))
        messages = self.converter.convert(stream, ros_type, record.data)
        return self._pairs(key, messages, record.log_time)

    def flush(self) -> list[Pair]:
        """The skeleton frame TF samples left open at the end of the bag, if any."""
        if self.converter is None:
            return []
        robots = {stream: robot for robot, stream in self.plan.routes.values()}
        key = Keys(robots.get("tf", DEFAULT_ROBOT)).skeleton
        return self._pairs(key, self.converter.flush(), None)

    def close(self) -> None:
        """Let the pose model go, if one was made."""
        if self.person is not None:
            self.person.close()
            self.person = None
