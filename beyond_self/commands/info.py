"""`beyond info KEY`: who publishes and who subscribes a key, its type, and its traffic now.

Zenoh does not list the peers on a key, so this asks the services: every `Service` reports its
inputs and outputs in its health (answered on query), and stays alive as a liveliness token.
A process that is not a service (a `beyond echo`, a replay) shows up only indirectly: as the
`source` in the headers heard while listening, and as "other subscribers" when a publisher
declared here matches one."""

from __future__ import annotations

import argparse
import asyncio
import json
from typing import Any

import zenoh

from beyond_self.commands import argtypes
from beyond_self.commands.bus_keys import check_key
from beyond_self.runtime.bus.cliargs import add_bus_arguments, config_from_args
from beyond_self.runtime.bus.rates import RateWindow
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.bus.subscription import decode_any
from beyond_self.schemas.codec import SchemaError, wire_encoding
from beyond_self.schemas.messages import ServiceHealth

HELP = "publishers, subscribers, type and traffic of a key"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("key", help="key, e.g. beyond/robot/sensors/skeleton")
    argtypes.add_listen_seconds(parser, "seconds to listen for traffic (default 2)")
    parser.add_argument("--json", action="store_true", help="one JSON object")
    add_bus_arguments(parser)


def _touches(patterns: list[str], key: zenoh.KeyExpr) -> bool:
    return any(zenoh.KeyExpr.autocanonize(p).intersects(key) for p in patterns)


async def gather(bus: Bus, key: str, duration: float) -> dict[str, Any]:
    """What the bus says of `key` over `duration` s. The services are asked for their health
    at the end of the window, not at its start: a session just opened has not met the others'
    queryables yet (a query then finds none and answers at once, while samples of the same
    services arrive moments later). A live service heard publishing on the key is a publisher
    even if its health did not answer, so the lines never contradict each other."""
    cls = check_key(key, bus.keys, concrete=True)
    assert cls is not None  # concrete=True: a key of ours
    expr = zenoh.KeyExpr(key)
    sub = bus.subscribe_raw(key, maxsize=1 << 16)
    probe = bus.publisher(key, cls)
    alive_now: set[str] = set()

    def token(found: str, present: bool) -> None:
        (alive_now.add if present else alive_now.discard)(found)

    unwatch = bus.watch_tokens(bus.keys.alive("*"), token)
    window = RateWindow(None)
    sources: set[str] = set()
    loop = asyncio.get_running_loop()
    deadline = loop.time() + duration
    while (remaining := deadline - loop.time()) > 0:
        try:
            sample = await sub.recv(remaining)
        except TimeoutError:
            break
        try:
            message = decode_any(sample)
        except SchemaError:
            continue
        if message is not None:
            sources.add(message.header.source)
            window.add(sample.received_ns, len(sample.payload), message.header.stamp)
    healths = await bus.query(bus.keys.health("*"), ServiceHealth, timeout=2.0, every=True)
    matching = probe.matching()
    unwatch()
    sub.close()
    probe.close()
    alive = sorted(alive_now)
    services = sorted(
        {r.message.service: r for r in healths}.values(), key=lambda r: r.message.service
    )
    answered = {r.message.service for r in services}
    live = {k.rsplit("/", 1)[-1] for k in alive}
    declared = [r.message.service for r in services if _touches(r.message.outputs, expr)]
    heard_live = [s for s in sorted(sources) if s in live or s in answered]
    stats = window.stats()
    return {
        "key": key,
        "type": cls.type_name(),
        "version": cls.VERSION,
        "schema": cls.schema_name(),
        "wire_encoding": wire_encoding(cls),
        "publishers": sorted({*declared, *heard_live}),
        # alive services whose health did not answer: the lines above may miss them
        "no_health": sorted(live - answered),
        "subscribers": [r.message.service for r in services if _touches(r.message.inputs, expr)],
        # a subscriber matching our probe publisher: a service or any other process
        "any_subscriber": matching,
        "alive": alive,
        "heard_from": sorted(sources),
        "messages": stats.count,
        "stamp_hz": stats.stamp_hz,
        "arrival_hz": stats.arrival_hz,
        "mean_bytes": stats.mean_bytes,
    }


def _names(names: list[str]) -> str:
    return ", ".join(names) if names else "none"


def run(args: argparse.Namespace) -> int:
    config = config_from_args(args)

    async def go() -> dict[str, Any]:
        with Bus.open(config) as bus:
            return await gather(bus, args.key, args.duration)

    info = asyncio.run(go())
    if args.json:
        print(json.dumps(info))
        return 0
    rate = "-" if info["stamp_hz"] is None else f"{info['stamp_hz']:.1f} Hz"
    print(f"key:          {info['key']}")
    print(f"type:         {info['type']} v{info['version']} (schema {info['schema']})")
    print(f"wire:         {info['wire_encoding']}")
    print(f"publishers:   {_names(info['publishers'])} (services: their health, or heard)")
    print(f"subscribers:  {_names(info['subscribers'])} (services, from their health)")
    print(f"any subscriber on the bus: {'yes' if info['any_subscriber'] else 'no'}")
    print(f"heard from:   {_names(info['heard_from'])} (header source, {args.duration:.1f} s)")
    if info["no_health"]:
        print(f"no health from: {_names(info['no_health'])} (alive, but did not answer)")
    print(f"traffic:      {info['messages']} messages, {rate} from stamps")
    return 0
