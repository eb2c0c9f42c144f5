"""Whether the link to the other side of a split carries data, not just presence.

After a cut link comes back, Zenoh 1.10 can leave the two sides' routers linked, each listing the
other side's liveliness tokens, while samples no longer cross, and it does not heal
(docs/decisions.md says why). The watch tells such a link from a cut one by what it still
carries: while a service of the other side is present and none of its health (published every
second) has arrived for `silent_s`, the side restarts its router (services.deployment), which
gives it a new identity; what was missed comes back from the caches. While the other side is
absent nothing is decided: that is a cut link, which Zenoh handles. The robot's router is also
restarted once per long outage, where it keeps listing the workstation.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable, Iterable

from beyond_self.runtime.bus.delivery import STATUS
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.bus.subscription import Subscription
from beyond_self.schemas.messages import ServiceHealth

SILENT_S = 12.0  # twelve health periods of every service of the other side, none arrived
CHECK_S = 1.0


class LinkSilence:
    """The decision, apart from the bus (tests drive it with their own clock): which remote
    services are present, when one of them was last heard, and whether the silence is long
    enough to call the link broken. `remote` are the names whose tokens and health count."""

    def __init__(self, remote: Iterable[str], silent_s: float = SILENT_S) -> None:
        self.remote = frozenset(remote)
        self.silent_s = silent_s
        self.present: set[str] = set()
        self.since: float | None = None  # when silence started to count (None: nobody there)
        self.broken = 0  # times the link was found broken

    def token(self, name: str, present: bool, now: float) -> None:
        """A remote service's token came or went. Silence counts from when the first one is
        present: health cannot arrive before its service is there."""
        if name not in self.remote:
            return
        was_empty = not self.present
        (self.present.add if present else self.present.discard)(name)
        if not self.present:
            self.since = None
        elif was_empty:
            self.since = now

    def heard(self, name: str, now: float) -> None:
        """A remote service's health arrived: the link carries data."""
        if name in self.remote and self.present:
            self.since = now

    def check(self, now: float) -> str | None:
        """Why the link is broken, once per silence (the count starts again from `now`), or
        None."""
        if self.since is None or now - self.since < self.silent_s:
            return None
        silent = now - self.since
        self.since = now
        self.broken += 1
        names = ", ".join(sorted(self.present))
        return (
            f"{names} present across the link but no health from the other side for "
            f"{silent:.0f} s: the link carries presence, not data"
        )


class LinkWatch:
    """`LinkSilence` on the bus: remote services' tokens and health, checked every `check_s`;
    `on_broken(why)` is called on the event loop when the link is found broken."""

    def __init__(
        self,
        bus: Bus,
        remote: Iterable[str],
        on_broken: Callable[[str], None],
        *,
        silent_s: float = SILENT_S,
        check_s: float = CHECK_S,
    ) -> None:
        self.bus, self.on_broken, self.check_s = bus, on_broken, check_s
        self.silence = LinkSilence(remote, silent_s)
        self._closers: list[Callable[[], None]] = []
        self._tasks: list[asyncio.Task[None]] = []

    def start(self) -> None:
        loop = asyncio.get_running_loop()
        keys = self.bus.keys

        def on_token(key: str, present: bool) -> None:
            self.silence.token(_last_chunk(key), present, loop.time())

        self._closers.append(self.bus.watch_tokens(keys.alive("*"), on_token))
        health = self.bus.subscribe(keys.health("*"), ServiceHealth, STATUS)
        self._closers.append(health.close)
        self._tasks = [
            loop.create_task(self._hear(health)),
            loop.create_task(self._check()),
        ]

    async def _hear(self, health: Subscription[ServiceHealth]) -> None:
        loop = asyncio.get_running_loop()
        async for received in health:
            self.silence.heard(_last_chunk(received.key), loop.time())

    async def _check(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            await asyncio.sleep(self.check_s)
            why = self.silence.check(loop.time())
            if why is not None:
                self.on_broken(why)

    async def stop(self) -> None:
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task
        for close in self._closers:
            close()
        self._closers.clear()


def _last_chunk(key: str) -> str:
    return key.rsplit("/", 1)[-1]
