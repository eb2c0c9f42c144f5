"""`beyond replay FILE.mcap`: publish a recording on the bus with its original timing."""

from __future__ import annotations

import argparse
import asyncio
import sys

from beyond.commands import argtypes
from beyond.commands.terminal import stop_on_signals
from cognition.errors import InputError
from runtime.bus import Bus
from runtime.cliargs import add_bus_arguments, config_from_args
from runtime.log import setup_logging
from runtime.recording import require_mcap
from runtime.replay import replay
from schemas.keys import check_name

HELP = "publish an MCAP recording on the bus in stamp order"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="MCAP recording")
    speed = parser.add_mutually_exclusive_group()
    speed.add_argument(
        "--rate",
        type=argtypes.number(float, lo=0, hi=1e6, lo_open=True),
        default=1.0,
        help="speed factor (default 1)",
    )
    speed.add_argument(
        "--as-fast-as-possible", "--afap", action="store_true", help="no timing, just go"
    )
    parser.add_argument("--loop", action="store_true", help="repeat until interrupted")
    parser.add_argument(
        "--topics", nargs="+", type=argtypes.keyexpr, metavar="KEYEXPR", help="only these keys"
    )
    parser.add_argument(
        "--start", type=argtypes.seconds(zero=True), help="seconds from the recording start"
    )
    parser.add_argument(
        "--end", type=argtypes.seconds(zero=True), help="seconds from the recording start"
    )
    parser.add_argument(
        "--wait-for",
        type=argtypes.keyexpr,
        metavar="KEYEXPR",
        help="before playing, wait until a liveliness token matches (e.g. beyond/r/alive/*)",
    )
    parser.add_argument(
        "--wait-timeout",
        type=argtypes.seconds(),
        default=30.0,
        metavar="S",
        help="give up on --wait-for after S seconds (default 30)",
    )
    parser.add_argument(
        "--pace-for",
        type=_names,
        metavar="NAME[,NAME...]",
        help="services never to outrun (default: every service alive when the replay starts; "
        "'none' for no pacing)",
    )
    add_bus_arguments(parser)


def _names(text: str) -> list[str]:
    """--pace-for: service names separated by commas, or 'none'."""
    if text.strip().lower() == "none":
        return []
    names = [n.strip() for n in text.split(",") if n.strip()]
    for name in names:
        check_name("service", name)
    return names


def run(args: argparse.Namespace) -> int:
    setup_logging(fmt="text")
    config = config_from_args(args)
    require_mcap(args.file)

    async def go() -> int:
        stop = stop_on_signals()
        with Bus.open(config) as bus:
            if args.wait_for:
                try:
                    await bus.wait_alive(args.wait_for, timeout=args.wait_timeout)
                except TimeoutError:
                    raise InputError(
                        f"nothing alive matched --wait-for {args.wait_for} within "
                        f"{args.wait_timeout:g} s (see `beyond topics`); nothing replayed"
                    ) from None
            if args.pace_for is None:
                alive = await bus.alive(bus.keys.alive("*"))
                pace_for = [key.rsplit("/", 1)[-1] for key in alive]
            else:
                pace_for = args.pace_for
            stats = await replay(
                bus,
                args.file,
                rate=None if args.as_fast_as_possible else args.rate,
                loop=args.loop,
                topics=args.topics,
                start=args.start,
                end=args.end,
                robot=config.robot,  # $BEYOND_ROBOT too, as recordings/README.md says
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
        if stats.damaged and stats.messages == 0:
            raise InputError(f"nothing replayed: {stats.damaged}")
        if stats.damaged:
            print(f"warning: {stats.damaged}", file=sys.stderr)
        return 0

    return asyncio.run(go())
