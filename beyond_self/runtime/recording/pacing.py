"""Backpressure for players: never run further ahead of the slowest consumer than a window.

A replay as fast as possible, or a paced one on a loaded machine, must lose nothing. Consumers
report the stamp of the last message they handled per sensor key (`Progress`), and how much they
received and published; before sending a message stamped `s`, the player waits until every
consumer of its key, and of what derives from it, is within `window` of `s`. The window holds
across streams, which bounds a camera's lead over the skeleton too. This decides only when the
player sends, never what anyone outputs. A consumer that disappears is waited for up to
`restart_wait_s` (a restarted one resumes from the caches), then no longer: a player must not hang
on a dead service. `handled_by_all` lets a restarted player go on where its consumers are.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable, Iterable
from typing import Any

from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.bus.subscription import consume
from beyond_self.schemas.messages import Progress, ServiceHealth

log = logging.getLogger("beyond.pacing")
DEFAULT_WINDOW_S = 0.5
_CHECK_ALIVE_S = 2.0  # waiting this long on a consumer: is it still there?
HEALTH_WAIT_S = 60.0  # asking a live consumer what it takes


class Pacer:
    def __init__(
        self,
        bus: Bus,
        consumers: Iterable[str],
        keys: Iterable[str],
        window_s: float = DEFAULT_WINDOW_S,
        restart_wait_s: float = 30.0,
    ) -> None:
        self.bus = bus
        self.names = list(consumers)
        self.keys = set(keys)
        self.window_ns = round(window_s * 1e9)
        self.takes: dict[str, set[str]] = {}  # consumer -> sensor keys it handles
        self.handled: dict[str, dict[str, int]] = {}
        self.sent: dict[str, int] = {}
        self.published: dict[str, dict[str, int]] = {}  # service -> key -> messages sent
        self.received: dict[str, dict[str, int]] = {}  # service -> key -> messages received
        self.waited_s = 0.0
        self.restart_wait_s = restart_wait_s
        self._gone_since: dict[str, float] = {}
        self._gone: set[str] = set()  # consumers whose token went and has not come back
        self.floor: dict[str, dict[str, int]] = {}  # consumer -> key -> last sent when it rejoined
        self._unwatch: Callable[[], None] | None = None
        self._relearn: asyncio.Task[None] | None = None
        self._moved = asyncio.Event()
        self._task: asyncio.Task[None] | None = None

    async def start(self) -> None:
        """Subscribe to progress, then learn what each (alive) consumer takes and how far it
        has got (its health and its Progress, asked)."""
        sub = self.bus.subscribe(self.bus.keys.progress(), Progress)

        def failed(key: str, exc: Exception) -> None:
            log.warning("progress on %s not understood: %s", key, exc)

        self._task = asyncio.get_running_loop().create_task(consume(sub, self.heard, failed))
        await asyncio.gather(*(self.learn(name) for name in self.names))
        self._unwatch = self.bus.watch_tokens(self.bus.keys.alive("*"), self._token)

    def _token(self, key: str, present: bool) -> None:
        """A consumer's liveliness token came or went: one that comes back after going is a
        new instance, waited for from now on (`rejoined`)."""
        name = key.rsplit("/", 1)[-1]
        if name not in self.names:
            return
        if not present:
            self._gone.add(name)
        elif name in self._gone:
            self._gone.discard(name)
            self.rejoined(name)

    def rejoined(self, name: str) -> None:
        """Consumer `name` was replaced: what its predecessor handled no longer says anything
        about it, and what was sent before it came back is waited for only as far as it gets
        it back (a publisher's cache): the player waits on the instance alive now, for what is
        sent from now on. Where a dead one's handling stopped is not a place anyone will pass
        again: a restarted consumer without history would stall the source there."""
        self._gone_since.pop(name, None)
        if name in self.handled:
            self.handled[name] = {}
        self.received.pop(name, None)
        self.floor[name] = dict(self.sent)
        if name not in self.takes:  # it was given up on: learn it again
            self._relearn = asyncio.get_running_loop().create_task(self.learn(name))
        self._moved.set()

    async def learn(self, name: str) -> None:
        """What consumer `name` takes (its health) and how far it has got (its Progress)."""
        for reply in await self._health(name):
            health = reply.message
            taken = set(health.inputs) & self.keys
            if taken:
                self.takes[name] = taken
            if self.bus.keys.progress(name) in health.outputs:
                self.handled.setdefault(name, {})  # it reports: wait for it from now
                with contextlib.suppress(Exception):  # then its next report says it
                    for got in await self.bus.query(self.bus.keys.progress(name), Progress):
                        self.heard(got.message)

    def heard(self, msg: Progress) -> None:
        mine = self.handled.setdefault(msg.service, {})
        for key, stamp in msg.handled.items():
            mine[key] = max(mine.get(key, -1), stamp)
        self.published[msg.service] = dict(msg.published)
        self.received[msg.service] = dict(msg.received)
        self._moved.set()

    def handled_by_all(self) -> dict[str, int]:
        """Per paced key, the last stamp every consumer taking it has handled (-1: none yet):
        where a restarted player goes on."""
        done: dict[str, int] = {}
        for name, taken in self.takes.items():
            handled = self.handled.get(name)
            if handled is None:
                continue
            for key in taken:
                done[key] = min(done.get(key, handled.get(key, -1)), handled.get(key, -1))
        return done

    async def _health(self, name: str) -> list[Any]:
        """The health reply of a consumer, asked again while it times out: on a busy machine
        one query can, and giving up would leave that consumer unpaced. An answer with no
        reply means nothing serves its health (a monitor): nothing to pace on."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + HEALTH_WAIT_S
        while True:
            try:
                return await self.bus.query(self.bus.keys.health(name), ServiceHealth, timeout=5.0)
            except Exception as exc:  # Zenoh's timeout comes back as an error reply
                if loop.time() > deadline or not await self.bus.live_tokens(
                    self.bus.keys.alive(name)
                ):
                    log.warning("consumer %s never answered its health query (%s)", name, exc)
                    return []

    def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
        if self._unwatch is not None:
            self._unwatch()
        if self._relearn is not None:
            self._relearn.cancel()

    def _behind(self, stamp: int) -> list[str]:
        published: dict[str, int] = {}
        for counts in self.published.values():
            for key, n in counts.items():
                published[key] = published.get(key, 0) + n
        behind = [
            name
            for name, counts in self.received.items()
            if name in self.takes
            and any(n < published[key] for key, n in counts.items() if key in published)
        ]
        for name, taken in self.takes.items():
            if name in behind or name not in self.handled:
                continue
            handled = self.handled.get(name, {})
            floor = self.floor.get(name, {})
            for key in taken:
                last = self.sent.get(key)
                if last is None:
                    continue
                needed = min(stamp - self.window_ns, last)
                if needed > floor.get(key, -1) and handled.get(key, -1) < needed:
                    behind.append(name)
                    break
        return behind

    async def before(self, key: str, stamp: int) -> None:
        """Wait until sending `stamp` (on `key`) keeps every consumer within the window on
        every stream it takes."""
        loop = asyncio.get_running_loop()
        began = None
        while behind := self._behind(stamp):
            began = began or loop.time()
            self._moved.clear()
            try:
                # asyncio.timeout, not wait_for: Python 3.11's wait_for can swallow the
                # cancellation that stops the service when the wait ends at the same moment,
                # and the source then played on past its SIGTERM until it was killed
                async with asyncio.timeout(_CHECK_ALIVE_S):
                    await self._moved.wait()
            except TimeoutError:
                for name in behind:
                    if await self.bus.live_tokens(self.bus.keys.alive(name)):
                        self._gone_since.pop(name, None)
                        continue
                    gone = self._gone_since.setdefault(name, loop.time())
                    if gone == loop.time():
                        log.warning("consumer %s is gone; waiting for it to come back", name)
                    elif loop.time() - gone > self.restart_wait_s:
                        log.warning("consumer %s did not come back; no longer waiting", name)
                        self.takes.pop(name, None)
        if began is not None:
            self.waited_s += loop.time() - began

    def after(self, key: str, stamp: int) -> None:
        self.sent[key] = max(self.sent.get(key, -1), stamp)
