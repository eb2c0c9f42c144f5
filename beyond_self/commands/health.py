"""`beyond health [SERVICE ...]`: exit 0 when the named services are on the bus.

A container's health check (Dockerfile HEALTHCHECK) cannot see a service's state from outside
the process; what matters to the rest of the deployment is whether the bus sees it, so this asks
the bus: a service is healthy when it answers a health query on its own key (its event loop is
serving, and its session is linked to ours). Without names, the services are the
`beyond service NAME` processes running here (in a container: the container's own), and a
`beyond router` process counts as healthy once a session to it opens. Exit 1 otherwise.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import time
from pathlib import Path

from beyond_self.commands import argtypes
from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.cliargs import add_bus_arguments, config_from_args
from beyond_self.runtime.bus.session import Bus
from beyond_self.schemas import ServiceHealth

HELP = "exit 0 when the named (default: locally running) services are alive on the bus"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("services", nargs="*", metavar="SERVICE", help="service names")
    parser.add_argument(
        "--timeout", type=argtypes.seconds(), default=5.0, help="seconds to wait (default 5)"
    )
    add_bus_arguments(parser)


def local_roles(proc: Path = Path("/proc")) -> tuple[list[str], bool]:
    """(service names, whether a router runs) of the `beyond` processes visible here."""
    services: list[str] = []
    router = False
    for cmdline in sorted(proc.glob("[0-9]*/cmdline")):
        try:
            argv = [a.decode() for a in cmdline.read_bytes().split(b"\0") if a]
        except OSError:
            continue  # exited meanwhile, or not ours to read
        rest = _beyond_args(argv)
        if rest[:1] == ["service"] and len(rest) > 1 and rest[1] not in services:
            services.append(rest[1])
        router = router or rest[:1] == ["router"]
    return services, router


def _beyond_args(argv: list[str]) -> list[str]:
    """The arguments after `beyond` (the console script, or `python -m beyond_self`); [] if none."""
    for i, arg in enumerate(argv):
        if Path(arg).name == "beyond" and argv[i - 1 : i] != ["-m"]:
            return argv[i + 1 :]
        if arg == "-m" and argv[i + 1 : i + 2] == ["beyond_self"]:
            return argv[i + 2 :]
    return []


def run(args: argparse.Namespace) -> int:
    names = list(args.services)
    router = False
    if not names:
        names, router = local_roles()
        if not names and not router:
            raise InputError("no SERVICE given and no `beyond service`/`beyond router` runs here")
    config = config_from_args(args)
    if router:  # our own router: a client session to it opens, or it is not serving
        config = config.with_(mode="client", connect=("tcp/127.0.0.1:7447",), config_file=None)
    # Never a listener of our own (a robot peer would advertise it to the group), and a bounded
    # wait for the first link: a workstation client would otherwise wait for its router forever.
    config = config.with_(listen=(), connect_timeout_ms=int(args.timeout * 1000))
    try:
        bus = Bus.open(config)
    except Exception as exc:  # zenoh's own error when no link opens in time
        print(f"unhealthy: cannot join the bus: {exc}", file=sys.stderr)
        return 1
    with bus:
        found = asyncio.run(_ask(bus, names, args.timeout))
        linked = not router or _router_linked(bus, args.timeout)
    missing = [n for n in names if n not in found]
    if missing:
        print(f"unhealthy: no health reply from {', '.join(missing)}", file=sys.stderr)
        return 1
    if not linked:
        print("unhealthy: no router at tcp/127.0.0.1:7447", file=sys.stderr)
        return 1
    for name in names:
        h = found[name]
        print(f"healthy: {name} up {h.uptime_s:.0f} s, in {h.messages_in}, out {h.messages_out}")
    if router:
        print("healthy: router accepts sessions")
    return 0


async def _ask(bus: Bus, names: list[str], timeout: float) -> dict[str, ServiceHealth]:
    """Each service's own answer to a health query (its event loop is serving), retried until
    `timeout`: the routes of a session just opened take a few links to fill in."""
    deadline = time.monotonic() + timeout
    found: dict[str, ServiceHealth] = {}
    while True:
        for name in [n for n in names if n not in found]:
            for reply in await bus.query(bus.keys.health(name), ServiceHealth, timeout=1.0):
                found[name] = reply.message
        if len(found) == len(names) or time.monotonic() > deadline:
            return found
        await asyncio.sleep(0.2)


def _router_linked(bus: Bus, timeout: float) -> bool:
    """Whether the session reached a router (a client session opens without one, and retries)."""
    deadline = time.monotonic() + timeout
    while not list(bus.session.info.routers_zid()):
        if time.monotonic() > deadline:
            return False
        time.sleep(0.1)
    return True
