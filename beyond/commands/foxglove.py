"""`beyond foxglove [--port 8765]`: watch the bus live in Foxglove (open a Foxglove WebSocket
connection to ws://localhost:8765; see README, "Watch the demo in Foxglove")."""

from __future__ import annotations

import argparse
import asyncio
import sys

from beyond.commands.terminal import stop_on_signals
from runtime.bus import Bus
from runtime.cliargs import add_bus_arguments, config_from_args
from runtime.foxglove_bridge import DEFAULT_PORT, FoxgloveBridge
from runtime.log import setup_logging

HELP = "serve the bus to Foxglove over its WebSocket protocol"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--port",
        dest="ws_port",
        type=int,
        default=DEFAULT_PORT,
        help=f"WebSocket port (default {DEFAULT_PORT})",
    )
    parser.add_argument("--host", default="127.0.0.1", help="address to listen on")
    add_bus_arguments(parser, port_flag="--bus-port")


def run(args: argparse.Namespace) -> int:
    setup_logging(fmt="text")
    config = config_from_args(args)

    async def go() -> int:
        stop = stop_on_signals()
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
        print(
            f"bridge stopped: {stats.received} samples, {stats.forwarded} messages forwarded, "
            f"{stats.malformed} malformed",
            file=sys.stderr,
        )
        return 0

    return asyncio.run(go())
