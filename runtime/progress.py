"""How far a service has got: the `Progress` it publishes for players, and resuming after a
restart.

A service's `paced` inputs (sensor streams) are the ones a player paces itself on
(runtime.pacing): after the handler of each message, so everything an input caused has been
published before its progress says so, the service reports the stamp of the last message it
handled per paced key, how many messages each subscription received and each publisher sent,
and the last stamp each publisher sent. A report is stamped by the service's clock (the stream's
on a replay, runtime.clock), like its health. A restarted instance asks the player for its
predecessor's last report and does not publish again what was already published.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import Any

from beyond_self.core.errors import InputError
from beyond_self.runtime.bus import Bus
from beyond_self.runtime.delivery import STATUS
from beyond_self.runtime.log import event
from beyond_self.runtime.publisher import Publisher
from beyond_self.schemas.base import Header
from beyond_self.schemas.messages import Progress


class ProgressReport:
    def __init__(self, name: str, header: Callable[[type[Progress]], Header]) -> None:
        self.name = name
        self.paced: set[str] = set()  # input keys whose handled stamps are reported
        self.handled: dict[str, int] = {}
        self._header = header
        self._pub: Publisher[Progress] | None = None

    def pace(self, key: str) -> None:
        self.paced.add(key)
        self.handled.setdefault(key, -1)

    def open(self, bus: Bus) -> None:
        """Start reporting: never blocking (a subscriber across a dead link, a remote monitor,
        must not stall the pipeline); a dropped report is repaired by the next, or by the
        periodic one beside health."""
        self._pub = bus.publisher(bus.keys.progress(self.name), Progress, STATUS)
        self._pub.put(
            Progress(header=self._header(Progress), service=self.name, handled=self.handled)
        )

    def handled_up_to(self, key: str, stamp: int) -> None:
        if key in self.paced:
            self.handled[key] = max(self.handled.get(key, -1), stamp)

    def publish(self, publishers: Sequence[Publisher[Any]], received: dict[str, int]) -> None:
        if self._pub is None:
            return
        self._pub.put(
            Progress(
                header=self._header(Progress),
                service=self.name,
                handled=self.handled,
                published={p.key: p.sent for p in publishers},
                received=received,
                published_stamps={p.key: p.last_stamp for p in publishers},
            )
        )


async def resume(
    bus: Bus, name: str, publishers: Sequence[Publisher[Any]], log: logging.Logger
) -> None:
    """Suppress in `publishers` what a previous instance of `name` already published: the
    player keeps the last `Progress` of every service it paces (runtime.pacing), which says up
    to which stamp each output key was published. No player, no answer: nothing to skip."""
    try:
        replies = await bus.query(bus.keys.progress(name), Progress, timeout=2.0)
    except (InputError, TimeoutError):
        return
    done = {k: v for r in replies for k, v in r.message.published_stamps.items()}
    for pub in publishers:
        pub.skip_until = max(pub.skip_until, done.get(pub.key, -1))
    if any(v >= 0 for v in done.values()):
        event(log, logging.INFO, "resuming after a previous instance", **done)
