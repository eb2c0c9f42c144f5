"""`beyond inspect FILE.mcap`: what a recording holds (works without the bus)."""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict
from typing import Any

from beyond_self.core.errors import InputError
from beyond_self.runtime.recording.reader import RecordingInfo, inspect_recording
from beyond_self.schemas.messages import Time

HELP = "list the channels, schemas, message counts and duration of an MCAP recording"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="MCAP recording")
    parser.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object (stamps as {sec, nsec}, exact in JavaScript)",
    )


def as_json(info: RecordingInfo) -> dict[str, Any]:
    """`info` as JSON, every stamp a Foxglove Time as in recordings (schemas.codec)."""

    def time(ns: int | None) -> dict[str, int] | None:
        if ns is None:
            return None
        t = Time.from_ns(ns)
        return {"sec": t.sec, "nsec": t.nsec}

    obj = {**asdict(info), "duration_s": info.duration_s}
    obj["start"], obj["end"] = time(info.start), time(info.end)
    for channel in obj["channels"]:
        channel["first_stamp"] = time(channel["first_stamp"])
        channel["last_stamp"] = time(channel["last_stamp"])
    return obj


def run(args: argparse.Namespace) -> int:
    info = inspect_recording(args.file)
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
    if info.error:
        raise InputError(info.damage())
    return 0
