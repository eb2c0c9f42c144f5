"""`beyond topics`: which keys are live right now, at what rate, carrying which type."""

from __future__ import annotations

import argparse
import asyncio
import time
from collections import defaultdict

from beyond.commands import argtypes
from runtime.bus import Bus
from runtime.cliargs import add_bus_arguments, config_from_args
from schemas.codec import type_from_encoding
from schemas.keys import type_for_key

HELP = "list live keys with message rates (and live services)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "keyexpr",
        nargs="?",
        type=argtypes.keyexpr,
        help="key expression to watch (default: beyond/<robot>/**)",
    )
    parser.add_argument(
        "--duration", type=argtypes.seconds(), default=2.0, help="seconds to listen"
    )
    add_bus_arguments(parser)


def run(args: argparse.Namespace) -> int:
    config = config_from_args(args)

    async def go() -> int:
        with Bus.open(config) as bus:
            keyexpr = args.keyexpr or bus.keys.everything
            sub = bus.subscribe_raw(keyexpr, maxsize=1 << 16)
            counts: dict[str, int] = defaultdict(int)
            sizes: dict[str, int] = defaultdict(int)
            types: dict[str, str] = {}
            loop = asyncio.get_running_loop()
            start = time.monotonic()
            deadline = loop.time() + args.duration
            while (remaining := deadline - loop.time()) > 0:
                try:
                    sample = await sub.recv(remaining)
                except TimeoutError:
                    break
                counts[sample.key] += 1
                sizes[sample.key] += len(sample.payload)
                cls = type_from_encoding(sample.encoding) or type_for_key(sample.key)
                types[sample.key] = cls.type_name() if cls else sample.encoding
            elapsed = time.monotonic() - start
            alive = await bus.alive(f"{bus.keys.root}/alive/**" if not args.keyexpr else "**")
        if not counts:
            print(f"no messages on {keyexpr} in {args.duration:.1f} s")
        width = max((len(k) for k in counts), default=0)
        for key in sorted(counts):
            rate = counts[key] / elapsed
            avg = sizes[key] / counts[key]
            print(f"{key:<{width}}  {rate:9.1f} Hz  {avg:9.0f} B  {types[key]}")
        for token in alive:
            print(f"alive: {token}")
        return 0

    return asyncio.run(go())
