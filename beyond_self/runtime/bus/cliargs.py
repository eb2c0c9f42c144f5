"""Bus options shared by every command that opens a Zenoh session."""

from __future__ import annotations

import argparse

from beyond_self.runtime.bus.config import CLIENT_WAIT_MS, ENV_VARS, MODES, BusConfig, load_config


def _port(text: str) -> int:
    """A TCP port, refused while parsing (argparse's int would take -1 or 10**100)."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 0 < value < 65536:
        raise argparse.ArgumentTypeError(f"{text!r} is not a TCP port; valid: 1-65535")
    return value


def add_bus_arguments(parser: argparse.ArgumentParser) -> argparse.Action:
    """The bus options, the same in every command (`--port` is always the rendezvous port of
    the local peer group); returns the `--port` option, for a command that keeps an older
    spelling of it."""
    group = parser.add_argument_group(
        "bus",
        "how to join the Zenoh network (defaults: " + "; ".join(f"{k}" for k in ENV_VARS) + ")",
    )
    group.add_argument("--robot", help="robot name, the second chunk of every key ($BEYOND_ROBOT)")
    group.add_argument("--mode", choices=MODES, help="Zenoh mode ($BEYOND_ZENOH_MODE)")
    group.add_argument(
        "--connect", action="append", metavar="ENDPOINT", help="endpoint to connect to (repeat)"
    )
    group.add_argument(
        "--listen", action="append", metavar="ENDPOINT", help="endpoint to listen on (repeat)"
    )
    group.add_argument("--zenoh-config", metavar="FILE", help="Zenoh JSON5 config file")
    port = group.add_argument(
        "--port",
        type=_port,
        help="rendezvous port of the local peer group ($BEYOND_ZENOH_PORT)",
    )
    group.add_argument(
        "--secure",
        metavar="DIR",
        help="keystore (`beyond keys init DIR`): mutual TLS via a router with access rules "
        "($BEYOND_ZENOH_SECURE)",
    )
    group.add_argument(
        "--identity",
        metavar="NAME",
        help="whose certificate in the keystore to present ($BEYOND_ZENOH_IDENTITY)",
    )
    return port


def config_from_args(args: argparse.Namespace) -> BusConfig:
    """The bus configuration the options say (over the environment's). A command that listens
    for `--duration` seconds waits no longer than that for a router to connect to."""
    config = load_config(
        robot=getattr(args, "robot", None),
        robots=getattr(args, "robots", None),
        standby=getattr(args, "standby", None),
        mode=getattr(args, "mode", None),
        connect=getattr(args, "connect", None),
        listen=getattr(args, "listen", None),
        config_file=getattr(args, "zenoh_config", None),
        port=getattr(args, "port", None),
        secure=getattr(args, "secure", None),
        identity=getattr(args, "identity", None),
    )
    duration = getattr(args, "duration", None)
    if isinstance(duration, int | float) and config.mode == "client":
        config = config.with_(connect_timeout_ms=max(1, min(CLIENT_WAIT_MS, int(duration * 1000))))
    return config
