"""Event time per source: which sensor messages a service takes, and whose time they move.

A sensor key (a `paced` input: one body tracker, one camera per robot) belongs to one source,
the header's `source` of the first message its handler accepts; a message from any other
publisher on it is foreign: refused, counted, never a clock. Within the owner's stream a
message not after the last one handled is a repeat when that very stamp was read (a restarted
source plays again from where its consumers need), else stale: lost; a jump forward is a
pause. A message the handler refuses as bad input moves nothing: no stream time, no owner; only
how far a player may count the stream as read.
docs/concepts/event-time.md says why.
"""

from __future__ import annotations

import enum
from array import array
from bisect import bisect_left, insort
from dataclasses import dataclass, field

UNOWNED_SOURCES = 16  # sources whose refused frames are remembered before a key has an owner
RECENT_STAMPS = 1024  # the owner's stamps read, kept (at most twice this) to tell a repeat


class Verdict(enum.Enum):
    FRESH = "fresh"  # the owner's (or the first accepted source's) and after its last: handle
    REPEAT = "repeat"  # a stamp of the owner's already read: a restarted source plays again
    STALE = "stale"  # not after the owner's last handled, and never read: out of order, lost
    FOREIGN = "foreign"  # from a source other than the key's owner


@dataclass(slots=True)
class _Stream:
    owner: str | None = None
    handled: int = -1  # the owner's last stamp handled: its time
    read: int = -1  # the owner's last stamp taken, handled or refused (flow control)
    unowned: dict[str, int] = field(default_factory=dict)  # no owner yet: last refused, by source
    recent: array[int] = field(default_factory=lambda: array("q"))  # owner's stamps read, sorted

    def remember(self, stamp: int) -> None:
        recent = self.recent
        if not recent or stamp > recent[-1]:
            recent.append(stamp)
        else:
            insort(recent, stamp)
        if len(recent) > 2 * RECENT_STAMPS:
            del recent[:RECENT_STAMPS]

    def seen(self, stamp: int) -> bool:
        i = bisect_left(self.recent, stamp)
        return i < len(self.recent) and self.recent[i] == stamp


class SourceTimes:
    """The per-source bookkeeping of a service's sensor inputs, apart from the bus: `verdict`
    before the handler, then `take` or `refuse` after it."""

    def __init__(self) -> None:
        self._streams: dict[str, _Stream] = {}
        self.stale = 0  # not after the owner's last handled and never read: lost
        self.repeated = 0  # read already: a restarted source playing again, nothing lost
        self.foreign = 0  # from a source other than the key's owner
        self.refused = 0  # refused by the handler as bad input

    def track(self, key: str) -> None:
        """Keep time on `key`, which will belong to the first source whose message is taken."""
        self._streams.setdefault(key, _Stream())

    def tracked(self, key: str) -> bool:
        return key in self._streams

    def owner(self, key: str) -> str | None:
        stream = self._streams.get(key)
        return None if stream is None else stream.owner

    def verdict(self, key: str, source: str, stamp: int) -> Verdict:
        """Whether to handle a message stamped `stamp` from `source` on `key`; a stale or
        foreign one is counted here."""
        stream = self._streams.get(key)
        if stream is None or stream.owner is None:
            return Verdict.FRESH
        if source != stream.owner:
            self.foreign += 1
            return Verdict.FOREIGN
        if stamp <= stream.handled:
            if stream.seen(stamp):
                self.repeated += 1
                return Verdict.REPEAT
            self.stale += 1
            return Verdict.STALE
        return Verdict.FRESH

    def why_foreign(self, key: str, source: str) -> str:
        """The one line said (once per source) when `source`'s messages on `key` are refused."""
        return (
            f"a message from source {source!r} on {key}, which belongs to "
            f"{self.owner(key)!r}: a sensor key takes one source (docs/concepts/event-time.md)"
        )

    def take(self, key: str, source: str, stamp: int) -> bool:
        """The handler took the message: the key becomes `source`'s if it had no owner, and
        the owner's time moves to `stamp`. False (nothing moves) for another source's."""
        stream = self._streams.get(key)
        if stream is None:
            return True
        if stream.owner is None:
            stream.owner = source
            stream.read = stream.unowned.get(source, -1)
            stream.unowned.clear()
        elif source != stream.owner:
            return False
        stream.handled = max(stream.handled, stamp)
        stream.read = max(stream.read, stamp)
        stream.remember(stamp)
        return True

    def refuse(self, key: str, source: str, stamp: int) -> None:
        """The handler refused the message as bad input: counted and forgotten (no time, no
        owner). Only how far the stream has been read moves (`progress`), so that a player
        waiting on this service (runtime.recording.pacing) passes a run of bad frames of its own,
        also
        at the start, before the key has an owner."""
        self.refused += 1
        stream = self._streams.get(key)
        if stream is None:
            return
        if stream.owner == source:
            stream.read = max(stream.read, stamp)
            stream.remember(stamp)
        elif stream.owner is None and (
            source in stream.unowned or len(stream.unowned) < UNOWNED_SOURCES
        ):
            stream.unowned[source] = max(stream.unowned.get(source, -1), stamp)

    def handled(self, key: str) -> int:
        """The owner's last stamp handled on `key` (-1: none): what a repeat is compared with."""
        stream = self._streams.get(key)
        return -1 if stream is None else stream.handled

    def progress(self, key: str, *, ceiling: int) -> int:
        """How far the owner's stream on `key` has been read, handled or refused (-1: none).
        Before the key has an owner, how far its refused frames go, but never past `ceiling`
        (the service's clock; on a replay, the player's): whose they were is not known yet,
        and a stranger's stamp must not tell the player more than its own clock does."""
        stream = self._streams.get(key)
        if stream is None:
            return -1
        if stream.owner is None:
            return min(max(stream.unowned.values(), default=-1), ceiling)
        return stream.read
