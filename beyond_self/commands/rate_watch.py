"""What `beyond hz` and `beyond bw` share: subscribe, keep a sliding window per key, print a line
per key every second and a last one when stopped (by --count, --duration or Ctrl-C)."""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import time
from collections.abc import Callable

from beyond_self.commands import argtypes
from beyond_self.commands.bus_keys import check_key
from beyond_self.commands.terminal import stop_on_signals
from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.cliargs import add_bus_arguments, config_from_args
from beyond_self.runtime.bus.rates import RateStats, RateWindow
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.bus.subscription import RawSample, decode_any
from beyond_self.schemas.codec import SchemaError

Show = Callable[[str, RateStats], str]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("key", help="key (e.g. beyond/robot/sensors/skeleton) or pattern with *")
    parser.add_argument(
        "--window",
        type=argtypes.seconds(),
        default=5.0,
        help="sliding window in seconds (default 5)",
    )
    parser.add_argument("--count", type=argtypes.count(), help="stop after this many messages")
    parser.add_argument("--duration", type=argtypes.seconds(), help="stop after this many seconds")
    parser.add_argument("--json", action="store_true", help="one JSON object per line")
    add_bus_arguments(parser)


def _stamp(sample: RawSample) -> int:
    try:
        message = decode_any(sample)
    except SchemaError:
        return 0
    return message.header.stamp if message is not None else 0


def run(args: argparse.Namespace, show: Show) -> int:
    if args.window <= 0:
        raise InputError(f"--window {args.window} must be a positive number of seconds")
    config = config_from_args(args)

    async def go() -> int:
        stop = stop_on_signals()
        loop = asyncio.get_running_loop()
        windows: dict[str, RateWindow] = {}
        seen = 0
        with Bus.open(config) as bus:
            check_key(args.key, bus.keys)
            sub = bus.subscribe_raw(args.key, maxsize=1 << 16)
            print(f"listening on {args.key}", file=sys.stderr, flush=True)
            deadline = None if args.duration is None else loop.time() + args.duration
            next_print = loop.time() + 1.0

            def report() -> None:
                now = time.time_ns()
                if not windows:
                    print(f"no messages on {args.key} yet", file=sys.stderr, flush=True)
                for key in sorted(windows):
                    windows[key].trim(now)
                    stats = windows[key].stats()
                    if args.json:
                        print(json.dumps({"key": key, **stats.as_dict()}), flush=True)
                    else:
                        print(show(key, stats), flush=True)

            while not stop.is_set() and (args.count is None or seen < args.count):
                now = loop.time()
                if deadline is not None and now >= deadline:
                    break
                if now >= next_print:
                    report()
                    next_print = now + 1.0
                timeout = next_print - now
                if deadline is not None:
                    timeout = min(timeout, deadline - now)
                try:
                    sample = await sub.recv(max(timeout, 0.0))
                except TimeoutError:
                    continue
                window = windows.get(sample.key)
                if window is None:
                    window = windows[sample.key] = RateWindow(args.window)
                window.add(sample.received_ns, len(sample.payload), _stamp(sample))
                seen += 1
            report()
        return 0

    return asyncio.run(go())


def hz(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f} Hz"


def seconds(value: float | None) -> str:
    return "-" if value is None else f"{value:.4f} s"
