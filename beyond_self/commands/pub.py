"""`beyond pub KEY TYPE JSON`: publish a message typed in by hand, checked against its schema.

The JSON is a line `beyond echo --json` prints (`{"key": ..., "message": {...}}`, whose key must
be KEY), or the message alone in the JSON form that line and recordings hold (every stamp a
Foxglove Time {"sec", "nsec"}, schemas.codec), without the parts a sender adds: `type` and
`header` may be left out (the header is filled in: this build's schema version, source
`beyond-pub`, a sequence number and the wall-clock stamp). Anything else is checked exactly as a
subscriber would check it, so a message refused here would have been refused by the services
too."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import sys
import time
from typing import Any

import msgspec

from beyond_self.commands import argtypes
from beyond_self.commands.bus_keys import check_key
from beyond_self.commands.terminal import stop_on_signals
from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.cliargs import add_bus_arguments, config_from_args
from beyond_self.runtime.bus.session import Bus
from beyond_self.schemas.base import Message
from beyond_self.schemas.codec import from_recording_object, lookup, to_recording_json

HELP = "publish one message (or a stream) given as JSON, validated against its schema"
SOURCE = "beyond-pub"
ECHO_LINE = ("key", "message")  # what `beyond echo --json` prints around a message


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("key", help="key, e.g. beyond/robot/language/description")
    parser.add_argument("type", help="message type, e.g. Description (see `beyond schemas`)")
    parser.add_argument(
        "json",
        help="a line `beyond echo --json` printed, or its message alone (stamps as {sec, nsec}; "
        "type and header may be left out); '-' reads it from stdin",
    )
    parser.add_argument(
        "--rate",
        type=argtypes.number(float, lo=0.0, hi=1e6, lo_open=True, what="Hz"),
        help="publish repeatedly at this rate (Hz)",
    )
    parser.add_argument(
        "--count", type=argtypes.count(), default=None, help="messages to send (default 1)"
    )
    parser.add_argument(
        "--wait",
        type=argtypes.seconds(zero=True),
        default=2.0,
        help="seconds to wait for a subscriber before sending (default 2; 0: do not wait)",
    )
    add_bus_arguments(parser)


def build(text: str, cls: type[Message], key: str, seq: int, stamp: int) -> Message:
    """The message `text` describes, header filled in where absent; SchemaError if invalid."""
    try:
        obj: Any = msgspec.json.decode(text)
    except msgspec.DecodeError as exc:
        raise InputError(f"JSON for {cls.type_name()} is not valid JSON: {exc}") from None
    if not isinstance(obj, dict):
        raise InputError(f"JSON for {cls.type_name()} must be an object, got {text[:40]!r}")
    obj = unwrap(obj, key)
    obj.setdefault("type", cls.type_name())
    now = {"sec": stamp // 1_000_000_000, "nsec": stamp % 1_000_000_000}
    obj.setdefault("header", {"version": cls.VERSION, "source": SOURCE, "seq": seq, "stamp": now})
    return from_recording_object(obj, cls, key)


def unwrap(obj: dict[str, Any], key: str) -> dict[str, Any]:
    """The message of a line `beyond echo --json` printed (`{"key", "message"}`), refused when
    it was heard on another key; any other object is the message itself."""
    if set(obj) != set(ECHO_LINE):
        return obj
    if obj["key"] != key:
        raise InputError(
            f"the JSON was heard on {obj['key']!r}, not on {key!r}; valid: the same key, or "
            "the message alone"
        )
    message = obj["message"]
    if not isinstance(message, dict):
        raise InputError(f"'message' of the JSON must be an object, got {str(message)[:40]!r}")
    return message


def run(args: argparse.Namespace) -> int:
    config = config_from_args(args)
    cls = lookup(args.type)
    text = sys.stdin.read() if args.json == "-" else args.json
    count = args.count if args.count is not None else (None if args.rate else 1)
    if args.rate is not None and args.rate <= 0:
        raise InputError(f"--rate {args.rate} must be positive (messages per second)")
    if count is not None and count < 1:
        raise InputError(f"--count {count} must be at least 1")
    build(text, cls, args.key, 0, time.time_ns())  # refuse bad input before joining the bus

    async def go() -> int:
        stop = stop_on_signals()
        with Bus.open(config) as bus:
            expected = check_key(args.key, bus.keys, concrete=True)
            if expected is not cls:
                name = expected.type_name() if expected else "?"
                raise InputError(f"{args.key} carries {name}, not {cls.type_name()}")
            pub = bus.publisher(args.key, cls)
            if args.wait > 0:
                try:
                    await pub.wait_matching(timeout=args.wait)
                except TimeoutError:
                    print(f"no subscriber on {args.key} yet; sending anyway", file=sys.stderr)
            sent = 0
            loop = asyncio.get_running_loop()
            start = loop.time()
            while not stop.is_set() and (count is None or sent < count):
                message = build(text, cls, args.key, sent, time.time_ns())
                pub.put(message)
                sent += 1
                if sent == 1:
                    print(to_recording_json(message).decode(), file=sys.stderr)
                if args.rate and (count is None or sent < count):
                    delay = start + sent / args.rate - loop.time()
                    if delay > 0:
                        with contextlib.suppress(TimeoutError):
                            await asyncio.wait_for(stop.wait(), delay)
            print(f"published {sent} {cls.type_name()} on {args.key}", file=sys.stderr)
        return 0

    return asyncio.run(go())
