"""`beyond topics`: which keys are live right now, at what rate, carrying which type."""

from __future__ import annotations

import argparse
import asyncio

from beyond_self.commands import argtypes
from beyond_self.runtime.bus.cliargs import add_bus_arguments, config_from_args
from beyond_self.runtime.bus.rates import RateWindow
from beyond_self.runtime.bus.session import Bus
from beyond_self.schemas.codec import type_from_encoding
from beyond_self.schemas.keys import type_for_key

HELP = "list live keys with message rates (and live services)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "keyexpr",
        nargs="?",
        type=argtypes.keyexpr,
        help="key expression to watch (default: beyond/<robot>/**)",
    )
    argtypes.add_listen_seconds(parser, "seconds to listen")
    add_bus_arguments(parser)


def run(args: argparse.Namespace) -> int:
    config = config_from_args(args)

    async def go() -> int:
        with Bus.open(config) as bus:
            keyexpr = args.keyexpr or bus.keys.everything
            sub = bus.subscribe_raw(keyexpr, maxsize=1 << 16)
            # Per key from its own first to last sample: dividing by the listening time would
            # under-report every key that started or stopped inside it (18 Hz for a 30 Hz one).
            windows: dict[str, RateWindow] = {}
            types: dict[str, str] = {}
            loop = asyncio.get_running_loop()
            deadline = loop.time() + args.duration
            while (remaining := deadline - loop.time()) > 0:
                try:
                    sample = await sub.recv(remaining)
                except TimeoutError:
                    break
                window = windows.get(sample.key)
                if window is None:
                    window = windows[sample.key] = RateWindow(None)
                window.add(sample.received_ns, len(sample.payload))
                cls = type_from_encoding(sample.encoding) or type_for_key(sample.key)
                types[sample.key] = cls.type_name() if cls else sample.encoding
            alive = await bus.live_tokens(f"{bus.keys.root}/alive/**" if not args.keyexpr else "**")
        if not windows:
            print(f"no messages on {keyexpr} in {args.duration:.1f} s")
        width = max((len(k) for k in windows), default=0)
        for key in sorted(windows):
            stats = windows[key].stats()
            rate = "       - Hz" if stats.arrival_hz is None else f"{stats.arrival_hz:9.1f} Hz"
            print(f"{key:<{width}}  {rate}  {stats.mean_bytes:9.0f} B  {types[key]}")
        for token in alive:
            print(f"alive: {token}")
        return 0

    return asyncio.run(go())
