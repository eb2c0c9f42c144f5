"""`beyond router`: a Zenoh router for deployments across machines."""

from __future__ import annotations

import argparse
import signal
import sys
import threading

import zenoh

from beyond_self.runtime.bus.cliargs import add_bus_arguments, config_from_args
from beyond_self.runtime.bus.config import ROUTER_LISTEN, describe
from beyond_self.runtime.bus.session import Bus
from beyond_self.services import registry

HELP = "run a Zenoh router (multi-host deployments); peers/clients connect to it"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_bus_arguments(parser)
    parser.epilog = f"Listens on {ROUTER_LISTEN} unless --listen or a config file says otherwise."


def run(args: argparse.Namespace) -> int:
    config = config_from_args(args).with_(mode="router")
    # A router's own errors (a rejected link, a routing table it cannot follow) are the only
    # account of why traffic stopped crossing it: shown, and RUST_LOG=zenoh=debug for more.
    zenoh.init_log_from_env_or("error")
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    rules = registry.access_rules(config.secure) if config.secure is not None else None
    with Bus.open(config, access_rules=rules) as bus:
        print(f"zenoh router {bus.zid} up: {describe(config)}", file=sys.stderr, flush=True)
        while not stop.wait(0.5):
            pass
    print("router stopped", file=sys.stderr)
    return 0
