"""`beyond replay FILE.mcap`: publish a recording on the bus with its original timing."""

from __future__ import annotations

import argparse
import asyncio
import sys

from beyond.commands.terminal import stop_on_signals
from runtime.bus import Bus
from runtime.cliargs import add_bus_arguments, config_from_args
from runtime.log import setup_logging
from runtime.replay import replay

HELP = "publish an MCAP recording on the bus in stamp order"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="MCAP recording")
    speed = parser.add_mutually_exclusive_group()
    speed.add_argument("--rate", type=float, default=1.0, help="speed factor (default 1)")
    speed.add_argument(
        "--as-fast-as-possible", "--afap", action="store_true", help="no timing, just go"
    )
    parser.add_argument("--loop", action="store_true", help="repeat until interrupted")
    parser.add_argument("--topics", nargs="+", metavar="KEYEXPR", help="only these keys")
    parser.add_argument("--start", type=float, help="seconds from the recording start")
    parser.add_argument("--end", type=float, help="seconds from the recording start")
    parser.add_argument(
        "--wait-for",
        metavar="KEYEXPR",
        help="before playing, wait until a liveliness token matches (e.g. beyond/r/alive/*)",
    )
    parser.add_argument(
        "--pace-for",
        metavar="NAME[,NAME...]",
        help="services never to outrun (default: every service alive when the replay starts; "
        "'none' for no pacing)",
    )
    add_bus_arguments(parser)


def run(args: argparse.Namespace) -> int:
    setup_logging(fmt="text")
    config = config_from_args(args)

    async def go() -> int:
        stop = stop_on_signals()
        with Bus.open(config) as bus:
            if args.wait_for:
                await bus.wait_alive(args.wait_for, timeout=30.0)
            if args.pace_for is None:
                alive = await bus.alive(bus.keys.alive("*"))
                pace_for = [key.rsplit("/", 1)[-1] for key in alive]
            elif args.pace_for.strip().lower() == "none":
                pace_for = []
            else:
                pace_for = [n.strip() for n in args.pace_for.split(",") if n.strip()]
            stats = await replay(
                bus,
                args.file,
                rate=None if args.as_fast_as_possible else args.rate,
                loop=args.loop,
                topics=args.topics,
                start=args.start,
                end=args.end,
                robot=args.robot,
                stop=stop,
                pace_for=pace_for,
            )
        print(
            f"replayed {stats.messages} messages in {stats.passes} pass(es), "
            f"{stats.span_s:.3f} s of recording in {stats.wall_s:.3f} s "
            f"({stats.speed:.1f}x real time; held back {stats.held_back_s:.3f} s by "
            f"{', '.join(pace_for) or 'nobody'})",
            file=sys.stderr,
        )
        if stats.damaged:
            print(f"warning: {stats.damaged}", file=sys.stderr)
        return 0

    return asyncio.run(go())
