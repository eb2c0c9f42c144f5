"""`beyond record KEYEXPR... -o FILE.mcap`: record live bus traffic."""

from __future__ import annotations

import argparse
import asyncio
import sys

from beyond_self.commands import argtypes
from beyond_self.commands.terminal import run_until_stopped
from beyond_self.runtime.bus.cliargs import add_bus_arguments, config_from_args
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.log import setup_logging
from beyond_self.runtime.recording.recorder import record
from beyond_self.runtime.recording.writer import COMPRESSIONS, DEFAULT_CHUNK_SIZE

HELP = "record bus traffic on key expressions into an MCAP file"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "keys",
        nargs="*",
        type=argtypes.keyexpr,
        metavar="KEYEXPR",
        help="key expressions (default: beyond/<robot>/**)",
    )
    parser.add_argument(
        "-o", "--output", type=argtypes.output_file, required=True, help="MCAP file to write"
    )
    parser.add_argument("--duration", type=argtypes.seconds(), help="stop after this many seconds")
    parser.add_argument("--count", type=argtypes.count(), help="stop after this many messages")
    parser.add_argument(
        "--chunk-size",
        type=argtypes.count(1024, 2**30, "bytes"),
        default=DEFAULT_CHUNK_SIZE,
        help=f"bytes of a chunk before it is closed (default {DEFAULT_CHUNK_SIZE:,})",
    )
    parser.add_argument(
        "--compression",
        choices=list(COMPRESSIONS),
        default="zstd",
        help="how chunks are compressed (default zstd)",
    )
    parser.add_argument(
        "--flush-interval",
        type=argtypes.seconds(),
        default=1.0,
        help="close a chunk at least this often (s)",
    )
    parser.add_argument(
        "--foxglove",
        action="store_true",
        help="also write the Foxglove views (3D skeleton, image annotations, plots, log)",
    )
    add_bus_arguments(parser)


def run(args: argparse.Namespace) -> int:
    setup_logging(fmt="text")
    config = config_from_args(args)

    async def go(stop: asyncio.Event) -> str:
        with Bus.open(config) as bus:
            keys = args.keys or [bus.keys.everything]
            print(f"recording {', '.join(keys)} -> {args.output}", file=sys.stderr, flush=True)
            stats = await record(
                bus,
                keys,
                args.output,
                stop=stop,
                duration=args.duration,
                count=args.count,
                chunk_size=args.chunk_size,
                compression=args.compression,
                flush_interval=args.flush_interval,
                metadata={"robot": config.robot, "keys": " ".join(keys)},
                foxglove_views=args.foxglove,
            )
        return (
            f"wrote {stats.messages} messages to {args.output} "
            f"({stats.malformed} malformed skipped, {stats.dropped} dropped)"
        )

    return run_until_stopped(go)
