"""A consumer of a numbered event stream, gated on its producer's progress: `Upstream`.

The gesture streamer's events carry their running count (`event_seq`), continued by a restarted
streamer and reported as published in its `Progress`. A consumer that subscribes with `complete=`
(`Service.subscribe`) gets from the base what counts as received for the player's pacing (the
highest count had, and at least the events of every gesture it closed before a restart, which a
restarted producer may not send again), and `complete(stamp)` once every event the producer
derived from its input up to `stamp` has arrived (told before the event that completes it is
handled).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Awaitable, Callable, Iterable
from typing import TypeVar

from beyond_self.schemas.base import Message
from beyond_self.schemas.messages import Description, ObjectEffects, Progress, WordProbabilities

M = TypeVar("M", bound=Message)
EVENTS_PER_GESTURE = 2  # a start, then an end or a cancel
# a service's last per-gesture output: the gesture is closed for it once every consumer has it
CLOSES: dict[type[Message], str] = {
    ObjectEffects: "effects",
    WordProbabilities: "words",
    Description: "description",
}


class Upstream:
    """The account of one numbered event key (`key`) from the producer `producer`."""

    def __init__(self, key: str, producer: str, complete: Callable[[int], None]) -> None:
        self.key = key
        self.producer = producer
        self.complete = complete
        self.arrived = 0  # the highest running count received
        self.before = 0  # the events of the gestures closed before a restart
        self._reports: deque[tuple[int, int]] = deque(maxlen=4096)  # (stamp, events published)

    def closed(self, gestures: Iterable[int]) -> None:
        """The gestures this service had closed before it was restarted."""
        closed = set(gestures)
        first_open = next(n for n in range(1, len(closed) + 2) if n not in closed)
        self.before = EVENTS_PER_GESTURE * (first_open - 1)

    @property
    def received(self) -> int:
        return max(self.arrived, self.before)

    def event(self, message: Message) -> None:
        """An event arrived (before its handler runs)."""
        self.arrived = max(self.arrived, getattr(message, "event_seq", 0))
        self._release()

    def progress(self, report: Progress) -> None:
        """The producer's progress: its input handled up to a stamp, its events published."""
        stamp = min(report.handled.values(), default=-1)
        self._reports.append((stamp, report.published.get(self.key, 0)))
        self._release()

    def _release(self) -> None:
        complete = -1
        while self._reports and self._reports[0][1] <= self.arrived:
            complete = self._reports.popleft()[0]
        if complete >= 0:
            self.complete(complete)


def counted(
    upstream: Upstream, handler: Callable[[M], Awaitable[None] | None]
) -> Callable[[M], Awaitable[None] | None]:
    """`handler`, with each message counted by `upstream` before it runs."""

    def count(message: M) -> Awaitable[None] | None:
        upstream.event(message)
        return handler(message)

    return count
