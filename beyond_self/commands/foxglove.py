"""`beyond foxglove [--ws-port 8765]`: watch the bus live in Foxglove (open a Foxglove WebSocket
connection to ws://localhost:8765; see docs/tutorial.md, "Watch it in Foxglove"). `--port` is the
bus's rendezvous port, as in every command (`--bus-port`, its spelling before 0.3, still works).

`beyond foxglove --export IN.mcap -o OUT.mcap` adds the same views to a recording made without
them (`beyond record --foxglove` writes them as it records), and what the pipeline publishes
for a recording of sensors alone, from the offline analysis (commands/foxglove_export.py)."""

from __future__ import annotations

import argparse
import asyncio
import sys
from pathlib import Path

from beyond_self.commands import argtypes
from beyond_self.commands.terminal import run_until_stopped
from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.cliargs import add_bus_arguments, config_from_args
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.foxglove.bridge import DEFAULT_PORT, FoxgloveBridge
from beyond_self.runtime.log import setup_logging

HELP = "serve the bus to Foxglove over its WebSocket protocol"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--ws-port",
        type=argtypes.number(int, lo=0, hi=65535, what="TCP port, 0: any free one"),
        default=DEFAULT_PORT,
        metavar="PORT",
        help=f"WebSocket port Foxglove connects to (default {DEFAULT_PORT}; 0: any free one)",
    )
    parser.add_argument(
        "--host", default="127.0.0.1", help="address the WebSocket listens on (default: loopback)"
    )
    parser.add_argument(
        "--export",
        metavar="IN.mcap",
        help="write IN.mcap plus its Foxglove views to -o FILE, with the pipeline's analysis "
        "(objects, posteriors, predictions, descriptions) where IN.mcap has sensors only",
    )
    argtypes.add_output(parser, "file written by --export")
    parser.add_argument(
        "--layout",
        metavar="FILE",
        help="write the Foxglove layout for --robot to FILE (import it in Foxglove) and exit",
    )
    argtypes.deprecated(parser, "--bus-port", add_bus_arguments(parser))


def run(args: argparse.Namespace) -> int:
    setup_logging(fmt="text")
    if args.layout:
        from beyond_self.runtime.foxglove.layout import layout_json

        robot = args.robot or config_from_args(args).robot
        Path(args.layout).write_text(layout_json(robot), encoding="utf-8")
        print(f"wrote the Foxglove layout for robot {robot!r} to {args.layout}")
        return 0
    if args.export or args.output:
        if not (args.export and args.output):
            raise InputError("--export IN.mcap needs -o OUT.mcap (and -o needs --export)")
        from beyond_self.commands.analyse import _inputs
        from beyond_self.commands.foxglove_export import export

        done = export(args.export, args.output, lambda p: _inputs(p, "right_hand", "torso"))
        print(f"wrote {done.copied} messages and their Foxglove views to {args.output}")
        if done.derived:
            added = ", ".join(f"{n} {stream}" for stream, n in done.derived.items())
            print(f"added the pipeline's analysis (beyond analyse's) with its views: {added}")
        for view, why in done.empty.items():
            print(f"view {view} is empty: {why}")
        return 0
    config = config_from_args(args)
    if args.port is not None:  # the one spelling whose meaning changed: say so
        argtypes.note(
            args,
            "--port is the bus's rendezvous port, as in every command; the WebSocket port is "
            "--ws-port (it was --port until 0.3)",
        )

    async def go(stop: asyncio.Event) -> str:
        with Bus.open(config) as bus:
            bridge = FoxgloveBridge(bus, host=args.host, port=args.ws_port)
            try:
                ready = asyncio.Event()
                task = asyncio.create_task(bridge.run(stop, ready))
                await ready.wait()
                print(
                    f"serving {bus.keys.everything} to Foxglove on ws://{args.host}:{bridge.port}",
                    file=sys.stderr,
                    flush=True,
                )
                stats = await task
            finally:
                bridge.close()
        return (
            f"bridge stopped: {stats.received} samples, {stats.forwarded} messages forwarded, "
            f"{stats.malformed} malformed"
        )

    return run_until_stopped(go)
