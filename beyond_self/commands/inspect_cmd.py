"""`beyond inspect FILE.mcap`: what a recording holds (works without the bus)."""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict
from typing import Any

from beyond_self.commands import argtypes
from beyond_self.core.errors import InputError
from beyond_self.runtime.recording.reader import RecordingInfo, inspect_recording
from beyond_self.schemas.messages import Time

HELP = "list the channels, schemas, message counts and duration of a recording or ROS 2 bag"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="MCAP recording, or a rosbag2 bag (folder or .mcap)")
    parser.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object (stamps as {sec, nsec}, exact in JavaScript)",
    )
    argtypes.add_ros2_topic(parser)


def as_json(info: RecordingInfo) -> dict[str, Any]:
    """`info` as JSON, every stamp a Foxglove Time as in recordings (schemas.codec)."""

    def time(ns: int | None) -> dict[str, int] | None:
        if ns is None:
            return None
        t = Time.from_ns(ns)
        return {"sec": t.sec, "nsec": t.nsec}

    obj = {**asdict(info), "duration_s": info.duration_s}
    obj["start"], obj["end"] = time(info.start), time(info.end)
    for channel in [*obj["channels"], *obj["ros2_topics"]]:
        channel["first_stamp"] = time(channel["first_stamp"])
        channel["last_stamp"] = time(channel["last_stamp"])
    return obj


def run(args: argparse.Namespace) -> int:
    roles = argtypes.ros2_roles(args)
    info = inspect_recording(args.file, roles)
    argtypes.check_ros2_roles(roles, info)
    for text in info.notes:
        argtypes.note(args, text)
    if args.json:
        print(json.dumps(as_json(info)))
    else:
        print(f"file:      {info.path} ({info.size} bytes)")
        print(f"library:   {info.library}")
        print(f"messages:  {info.messages} in {info.chunks} chunks")
        print(f"duration:  {info.duration_s:.3f} s")
        for name, values in info.metadata.items():
            print(f"metadata:  {name}: {values}")
        print("channels:")
        width = max((len(c.topic) for c in info.channels), default=10)
        for c in info.channels:
            rate = ""
            if c.count > 1 and c.first_stamp is not None and c.last_stamp is not None:
                span = (c.last_stamp - c.first_stamp) / 1e9
                rate = f"{(c.count - 1) / span:8.1f} Hz" if span > 0 else ""
            schema = f"{c.schema_name} ({c.schema_encoding})" if c.schema_name else "(no schema)"
            print(
                f"  {c.topic:<{width}}  {c.count:7d} msgs {rate:>11}  {c.message_encoding:6} "
                f"{schema}"
            )
        if info.ros2_topics:
            ros2_table(info)
    if info.error:
        raise InputError(info.damage())
    return 0


def ros2_table(info: RecordingInfo) -> None:
    """A ROS 2 bag's own topics: type, messages, and the stream of ours each is read as."""
    print("ROS 2 topics:")
    width = max(len(c.topic) for c in info.ros2_topics)
    kind = max(len(c.schema_name) for c in info.ros2_topics)
    for c in info.ros2_topics:
        stream = info.ros2_read_as.get(c.topic, "")
        read = f"read as {stream}" if stream else "not read"
        print(f"  {c.topic:<{width}}  {c.schema_name:<{kind}}  {c.count:7d} msgs  {read}")
