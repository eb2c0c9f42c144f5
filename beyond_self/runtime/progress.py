"""How far a service has got: the `Progress` it publishes for players (runtime.recording.pacing).

After the handler of each message on a `paced` input (so everything it caused is published
first), the service reports the last stamp handled per paced key, what each subscription received
and each publisher sent, stamped by the service's clock. It answers for it on query too, so a
player that starts, or starts again, learns at once where every consumer is. The report after
each message goes out only while someone subscribes (`wanted`); live, nobody paces on it, and it
cost a tenth of a fleet gesture streamer's time at 96 robots.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

from beyond_self.runtime.bus.delivery import STATUS
from beyond_self.runtime.bus.publisher import Publisher
from beyond_self.runtime.bus.session import Bus
from beyond_self.schemas.base import Header
from beyond_self.schemas.messages import Progress


class ProgressReport:
    def __init__(self, name: str, header: Callable[[type[Progress]], Header]) -> None:
        self.name = name
        self.paced: set[str] = set()  # input keys whose handled stamps are reported
        self.handled: dict[str, int] = {}
        self._header = header
        self._pub: Publisher[Progress] | None = None
        self.wanted = False  # a subscriber matches the report's key now

    def pace(self, key: str) -> None:
        self.paced.add(key)
        self.handled.setdefault(key, -1)

    def open(self, bus: Bus, first: Progress) -> None:
        """Start reporting: never blocking (a subscriber across a dead link, a remote monitor,
        must not stall the pipeline); a dropped report is repaired by the next, or by the
        periodic one beside health."""
        self._pub = bus.publisher(bus.keys.progress(self.name), Progress, STATUS)
        bus.on_close(self._pub.watch_matching(self._matched))
        self.wanted = self._pub.matching()
        self._pub.put(first)

    def _matched(self, matching: bool) -> None:  # Zenoh thread
        self.wanted = matching

    def handled_up_to(self, key: str, stamp: int) -> None:
        if key in self.paced:
            self.handled[key] = max(self.handled.get(key, -1), stamp)

    def report(
        self,
        published: Mapping[str, int],
        received: Mapping[str, int],
        published_stamps: Mapping[str, int],
    ) -> Progress:
        """The Progress now: handled stamps, and the counts the caller gives."""
        return Progress(
            header=self._header(Progress),
            service=self.name,
            handled=dict(self.handled),
            published=dict(published),
            received=dict(received),
            published_stamps=dict(published_stamps),
        )

    def publish(self, progress: Progress) -> None:
        if self._pub is not None:
            self._pub.put(progress)
