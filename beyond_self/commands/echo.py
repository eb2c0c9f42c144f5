"""`beyond echo KEYEXPR`: print decoded messages as they arrive.

The key is checked as `hz`, `bw` and `info` check theirs (commands.bus_keys): a key of ours or
a pattern with `*`; anything else is one line and exit status 2 at once, not a silent wait for
messages no stream will ever carry."""

from __future__ import annotations

import argparse
import asyncio
import sys

from beyond_self.commands import argtypes
from beyond_self.commands.bus_keys import check_key
from beyond_self.commands.terminal import stop_on_signals
from beyond_self.runtime.bus.cliargs import add_bus_arguments, config_from_args
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.bus.subscription import decode_any
from beyond_self.schemas.codec import SchemaError, to_recording_json

HELP = "print the messages on a key expression, decoded"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "keyexpr", type=argtypes.keyexpr, help="key expression, e.g. beyond/robot/sensors/skeleton"
    )
    parser.add_argument(
        "--json",
        action="store_true",
        help="one JSON object per line, in the recordings' JSON form (stamps as {sec, nsec})",
    )
    parser.add_argument("--count", type=argtypes.count(), help="stop after this many messages")
    parser.add_argument("--duration", type=argtypes.seconds(), help="stop after this many seconds")
    add_bus_arguments(parser)


def run(args: argparse.Namespace) -> int:
    config = config_from_args(args)

    async def go() -> int:
        stop = stop_on_signals()
        loop = asyncio.get_running_loop()
        shown = 0
        deadline = None if args.duration is None else loop.time() + args.duration
        with Bus.open(config) as bus:
            check_key(args.keyexpr, bus.keys)
            sub = bus.subscribe_raw(args.keyexpr)
            while not stop.is_set() and (args.count is None or shown < args.count):
                timeout = 0.2 if deadline is None else min(0.2, deadline - loop.time())
                if timeout <= 0:
                    break
                try:
                    sample = await sub.recv(timeout)
                except TimeoutError:
                    continue
                try:
                    message = decode_any(sample)
                except SchemaError as exc:
                    print(f"{sample.key}: malformed: {exc}", file=sys.stderr, flush=True)
                    continue
                if message is None:
                    text = f"<{len(sample.payload)} bytes, {sample.encoding}>"
                    line = f'{{"key":"{sample.key}","raw":"{text}"}}' if args.json else text
                elif args.json:
                    text = to_recording_json(message).decode()  # stamps as {sec, nsec}
                    line = f'{{"key":"{sample.key}","message":{text}}}'
                else:
                    line = repr(message)
                print(line if args.json else f"{sample.key}: {line}", flush=True)
                shown += 1
        return 0

    return asyncio.run(go())
