"""Watching a side of `beyond up` run: the event lines and the live view, the services it still
waits for, another `up` already on the bus, and why the run ended."""

from __future__ import annotations

import asyncio
import sys
import time
from collections.abc import Callable

from rich.console import Console
from rich.live import Live

from beyond_self.live_view import render
from beyond_self.monitor import PipelineMonitor
from beyond_self.runtime.bus.session import Bus
from beyond_self.schemas.keys import Keys
from beyond_self.services.deployment import Deployment, Ending

ALIVE_QUERY_S = 2.0  # how long the services already on the bus have to answer
HINT_S = 5.0  # how often `up` says which service it still waits for, and how to start it


class EventLines:
    """Where pipeline events go: above the live view while it runs, else plain stdout lines."""

    def __init__(self) -> None:
        self.live: Live | None = None

    def emit(self, line: str) -> None:
        if self.live is not None:
            self.live.console.print(line, markup=False, highlight=False)
        else:
            print(line, flush=True)


def log_line(name: str, line: str) -> None:
    print(f"[{name}] {line}", file=sys.stderr, flush=True)


async def already_up(side: Deployment, bus: Bus) -> list[str]:
    """The services (and monitor) of this side already alive on the bus for its robot: those of
    another `beyond up`. Two sets of the same services on one robot's keys would each take the
    other's messages for their own. Alone on the bus (no peer, no router), nothing is; else
    each token is waited for ALIVE_QUERY_S at most: a peer's session learns the others' tokens
    as it meets them, after it has met the rendezvous peer (`up`'s own session)."""
    info = bus.session.info
    if not list(info.peers_zid()) and not list(info.routers_zid()):
        return []
    keys = {n: Keys(u.robot).alive(u.service) for n, u in side.units.items()}
    if side.watcher:
        keys[side.watcher] = bus.keys.alive(side.watcher)
    seen = await asyncio.gather(
        *(bus.wait_alive(key, timeout=ALIVE_QUERY_S) for key in keys.values()),
        return_exceptions=True,
    )
    return [name for name, got in zip(keys, seen, strict=True) if isinstance(got, set)]


async def say_what_is_awaited(
    bus: Bus,
    awaited: dict[str, str],
    period: float = HINT_S,
    say: Callable[[str], None] | None = None,
) -> None:
    """Every `period` s, until each service of `awaited` is on the bus, say on stderr which are
    not and how to start one: a side waiting on a service nobody started waits in silence."""
    say = say or (lambda text: print(f"[up] {text}", file=sys.stderr, flush=True))
    robot = bus.keys.robot
    while awaited:
        await asyncio.sleep(period)  # a timer for the terminal: nothing waits on it
        found = await bus.live_tokens(bus.keys.alive("*"), timeout=ALIVE_QUERY_S)
        alive = {key.rsplit("/", 1)[-1] for key in found}
        awaited = {n: why for n, why in awaited.items() if n not in alive}
        for name, why in awaited.items():
            say(
                f"waiting for {name} ({why}: it runs elsewhere); start it on this bus, e.g. "
                f"`beyond service {name} --robot {robot}`"
            )


async def watch(
    side: Deployment,
    pipeline: PipelineMonitor,
    lines: EventLines,
    timeout: float | None,
    finite: bool,
    *,
    live: bool,
) -> Ending:
    """Wait for the side to end, with the live view drawn meanwhile on a terminal; say why it
    ended unless it was asked to or done. `timeout` bounds start-up and the tail after the
    source's end (`PipelineMonitor.waited_too_long`), never a running source's silence."""
    console = Console()
    if live and console.is_terminal:
        view = lambda: render(pipeline, side.services)  # noqa: E731
        lines.live = Live(get_renderable=view, console=console, refresh_per_second=8)
        lines.live.start()
    since = time.monotonic()
    timed_out = False

    def over() -> bool:
        nonlocal timed_out
        if finite and pipeline.done():
            return True
        timed_out = timeout is not None and pipeline.waited_too_long(timeout, since)
        return timed_out

    try:
        ending = await side.wait(done=over)
        if timed_out:
            ending = Ending("timeout")
    finally:
        if lines.live is not None:
            lines.live.stop()  # drawn once more, as it ends
            lines.live = None
    if ending.reason == "exited":
        why = {n: side.restarts[n].gave_up for n in ending.exited if n in side.restarts}
        said = [f"{n} ({why[n]})" if why.get(n) else n for n in ending.exited]
        lines.emit(f"service(s) exited early: {', '.join(said)}")
    elif ending.reason == "timeout":
        lines.emit(f"timed out after {timeout:.0f} s")
    return ending
