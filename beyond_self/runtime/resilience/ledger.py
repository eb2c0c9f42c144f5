"""Exactly once at the consumer: what each service has handled, by identity, and who knows it.

Every per-gesture and per-frame output has an identity (schemas.identity). Three rules, applied
by the Service base, make a killed and restarted service neither stall nor repeat anything
(docs/concepts/exactly-once.md): a consumer acts on each identity once (`Handled`); a restarted
producer does not send again what every consumer of its key has handled, once its gesture is
said (`Ledger`s published and kept by everyone, `LedgerBook`); and a service whose handling is
a side effect takes its predecessor's `Handled` for those inputs (`once`). What a service has
handled only grows, so several copies of one ledger are merged; its `resume` numbers come from
the newest copy.
"""

from __future__ import annotations

import asyncio
import bisect
import contextlib
import logging
import time
from collections.abc import Callable, Coroutine, Iterable, Mapping
from typing import Any

import msgspec

from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.delivery import STATUS
from beyond_self.runtime.bus.publisher import Publisher
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.bus.subscription import consume
from beyond_self.runtime.log import event
from beyond_self.runtime.resilience.state import LedgerFile
from beyond_self.schemas.base import Header, Message
from beyond_self.schemas.identity import GESTURE_KINDS, Identity, identify
from beyond_self.schemas.messages import LEDGER_RANGES, InputPosition, Ledger, Range

SEGMENTS_KEPT = 256  # per key and kind: older segments are forgotten (no cache holds them)
RANGES_KEPT = 64  # per key, kind and segment: older ranges are forgotten
SEGMENT_EVENTS = ("start", "end", "cancel")


class Position(msgspec.Struct, frozen=True):
    """A sensor key where a successor needs its input from, to derive `gesture` again (None:
    from its newest snapshot); a ledger tells the first stamp it needs there."""

    key: str
    gesture: int | None = None


def on_the_wire(positions: Mapping[Position, int]) -> list[InputPosition]:
    return [InputPosition(p.key, stamp, p.gesture) for p, stamp in positions.items()]


class Handled:
    """Identities handled, per input key: kind -> segment -> sorted, disjoint [first, last]
    ranges of frames. Bounded: forgetting (the oldest segments, the oldest ranges) only ever
    makes a producer send more, never less."""

    def __init__(self) -> None:
        self.keys: dict[str, dict[str, dict[int, list[list[int]]]]] = {}

    def declare(self, key: str) -> None:
        """`key` is taken, so it is listed (and its producers learn it is wanted) before any
        message on it has been handled."""
        self.keys.setdefault(key, {})

    def has(self, key: str, ident: Identity) -> bool:
        ranges = self.keys.get(key, {}).get(ident.kind, {}).get(ident.segment_id)
        if not ranges:
            return False
        i = bisect.bisect_right(ranges, [ident.frame, float("inf")]) - 1
        return i >= 0 and ranges[i][0] <= ident.frame <= ranges[i][1]

    def add(self, key: str, ident: Identity) -> bool:
        """Record `ident` handled on `key`; whether it was new."""
        if self.has(key, ident):
            return False
        self._add_range(key, ident.kind, ident.segment_id, ident.frame, ident.frame)
        return True

    def _add_range(self, key: str, kind: str, segment: int, first: int, last: int) -> None:
        segments = self.keys.setdefault(key, {}).setdefault(kind, {})
        ranges = segments.get(segment)
        if ranges is None:
            ranges = segments[segment] = []
            if len(segments) > SEGMENTS_KEPT:
                del segments[min(segments)]
        if ranges and ranges[-1][0] <= first <= ranges[-1][1] + 1:
            # the next frame of a stream (every message but a restart's): it extends the last
            # range, and ranges are disjoint and sorted, so no other range is touched
            ranges[-1][1] = max(ranges[-1][1], last)
            return
        i = bisect.bisect_left(ranges, [first, first])
        ranges.insert(i, [first, last])
        merged: list[list[int]] = []
        for lo, hi in ranges:  # short lists: merge overlapping and adjacent ranges
            if merged and lo <= merged[-1][1] + 1:
                merged[-1][1] = max(merged[-1][1], hi)
            else:
                merged.append([lo, hi])
        ranges[:] = merged[-RANGES_KEPT:]

    def segments(self, key: str, kind: str) -> set[int]:
        """Segment ids with `kind` handled on `key`."""
        return set(self.keys.get(key, {}).get(kind, {}))

    # -- on the wire ------------------------------------------------------------------------

    def wire(self) -> dict[str, dict[str, list[Range]]]:
        out: dict[str, dict[str, list[Range]]] = {}
        for key, kinds in self.keys.items():
            out[key] = {}
            for kind, segments in kinds.items():
                flat = [(s, lo, hi) for s, ranges in segments.items() for lo, hi in ranges]
                out[key][kind] = flat[-LEDGER_RANGES:]
        return out

    def merge(
        self,
        handled: Mapping[str, Mapping[str, Iterable[Range]]],
        keys: Iterable[str] | None = None,
    ) -> None:
        """Add what another record says was handled (on `keys` only, if given)."""
        wanted = None if keys is None else set(keys)
        for key, kinds in handled.items():
            if wanted is not None and key not in wanted:
                continue
            self.declare(key)
            for kind, ranges in kinds.items():
                for segment, first, last in ranges:
                    self._add_range(key, kind, segment, first, last)


class LedgerBook:
    """The last word of every service of a robot on what it handled (its own `Ledger`s, heard
    or asked): merged over its instances (what was done, what a successor takes over), and
    that of its newest instance alone (what the one alive now has)."""

    def __init__(self) -> None:
        self.handled: dict[str, Handled] = {}
        self.current: dict[str, tuple[int, Handled]] = {}  # service -> (instance, its handled)
        self.resume: dict[str, tuple[int, dict[str, int]]] = {}  # service -> (stamp, numbers)
        self.positions: dict[str, tuple[int, list[InputPosition]]] = {}  # service -> (stamp, ...)
        self.last: dict[str, Ledger] = {}  # as heard, to answer for the service
        self.past: dict[str, int] = {}  # service -> its newest instance known to be dead
        self.version = 0  # one more with every ledger heard: what was derived from it is stale

    def heard(self, ledger: Ledger, *, alive: bool = True) -> None:
        """Take `ledger` in; `alive=False`: kept on disk by an instance that died (the whole
        deployment was killed), so what it handled is done but nothing it has now."""
        name = ledger.service
        self.version += 1
        self.handled.setdefault(name, Handled()).merge(ledger.handled)
        if not alive:
            # not answered for (`last`): whoever heard it from us would take it for alive, and
            # withhold from the successor what the dead instance had
            self.past[name] = max(self.past.get(name, -1), ledger.instance)
        else:
            instance, handled = self.current.get(name, (-1, Handled()))
            if ledger.instance > instance:
                instance, handled = ledger.instance, Handled()
                self.current[name] = (instance, handled)
            if ledger.instance == instance:
                handled.merge(ledger.handled)
                self.last[name] = ledger
        stamp, _ = self.resume.get(name, (-1, {}))
        numbers = {**ledger.resume, **ledger.resume_stamps}
        if numbers and ledger.header.stamp >= stamp:
            self.resume[name] = (ledger.header.stamp, numbers)
        stamp, _ = self.positions.get(name, (-1, {}))
        if ledger.positions and ledger.header.stamp >= stamp:
            self.positions[name] = (ledger.header.stamp, list(ledger.positions))

    def instance_of(self, service: str) -> int:
        """The newest instance of `service` heard of (-1: none)."""
        return max(self.current.get(service, (-1, Handled()))[0], self.past.get(service, -1))

    def resume_of(self, service: str) -> dict[str, int]:
        return dict(self.resume.get(service, (-1, {}))[1])

    def needed(self, keys: Iterable[str], back_to: int | None = None) -> dict[str, int]:
        """Per key of `keys`, the oldest input position of any service's snapshot; with
        `back_to` (a gesture not said yet), each service's position for the highest gesture N
        up to it where it has one (from there its successor derives gesture N again)."""
        wanted = set(keys)
        out: dict[str, int] = {}
        for _, positions in self.positions.values():
            mine: dict[str, tuple[int, int]] = {}  # key -> (N, stamp); N = -1: the newest
            for p in positions:
                n = -1 if p.gesture is None else p.gesture
                if p.key not in wanted:
                    continue
                if p.gesture is not None and (back_to is None or not 0 <= n <= back_to):
                    continue
                if p.key not in mine or n > mine[p.key][0]:
                    mine[p.key] = (n, p.stamp)
            for key, (_, stamp) in mine.items():
                out[key] = min(stamp, out.get(key, stamp))
        return out

    def consumers_have(self, key: str, ident: Identity, producer: str) -> bool:
        """Every service (but `producer`) that takes `key` has handled `ident` in its instance
        alive now, and there is at least one: what a restarted producer need not send again.
        A consumer restarted too has handled none of it yet, and may need it to rebuild its
        state (the object segmenter, a gesture under way)."""
        takers = [n for n, h in self.handled.items() if n != producer and key in h.keys]
        if not takers:
            return False
        for name in takers:
            instance, handled = self.current.get(name, (-1, None))
            # known only from its state folder, as an instance that died: its successor is not
            # heard yet, and has nothing
            if handled is None or instance < self.past.get(name, -1):
                return False
            if not handled.has(key, ident):
                return False
        return True

    def done(self, key: str, kind: str, producer: str) -> set[int]:
        """Segments whose `kind` on `key` every service (but `producer`) taking it has handled
        (none when nobody takes it)."""
        takers = [h for n, h in self.handled.items() if n != producer and key in h.keys]
        if not takers:
            return set()
        return set.intersection(*(h.segments(key, kind) for h in takers))

    def delivered(self, key: str, producer: str) -> set[int] | None:
        """Segments of which every service (but `producer`) taking `key` has handled a
        per-gesture result (None when nobody takes it)."""
        takers = [h for n, h in self.handled.items() if n != producer and key in h.keys]
        if not takers:
            return None
        return set.intersection(
            *({s for kind in set(h.keys[key]) & GESTURE_KINDS for s in h.segments(key, kind)}
              for h in takers)
        )  # fmt: skip

    def taken(self, key: str, producer: str) -> bool:
        """Some service (but `producer`) takes `key`: its identities are worth checking."""
        return any(key in h.keys for n, h in self.handled.items() if n != producer)


# asking the others for the ledgers at start: answered at once by idle services, but a service
# busy on a loaded machine may take seconds, and its answer is what keeps a sentence from being
# said twice (the query ends as soon as every service has answered)
ASK_TIMEOUT_S = 10.0
# a restarted service asks again until its predecessor's record is among the answers: a session
# just opened may not know the others' queryables yet, and its first query then ends at once
# with no answer at all; taking itself for a first instance, a restarted reasoner would wait
# for a gesture its predecessor had finished, and a restarted speech service say a sentence again
ASK_AGAIN_S = 0.1


class Keeper:
    """A service's part in exactly-once: its own `Handled`, the `LedgerBook` of the others', its
    `Ledger` published and answered for, and the checks the Service base makes with them."""

    def __init__(self, name: str, header: Callable[[type[Ledger], int | None], Header]) -> None:
        self.name = name
        self.handled = Handled()
        self.book = LedgerBook()
        self.instance = 0  # its predecessor's plus one, once it has asked
        self.duplicates = 0  # messages skipped: their identity was handled already
        # what this service's next instance resumes from (its checkpoint)
        self.resume: dict[str, int] = {}
        self.resume_stamps: dict[str, int] = {}
        self.positions: dict[Position, int] = {}  # -> the first stamp a successor needs there
        self._header = header
        self._pub: Publisher[Ledger] | None = None
        self._dirty = False
        self.file: LedgerFile | None = None  # kept on this machine too (a state folder)
        self.kept = Handled()  # what its predecessors handled, as its state folder says
        self.said_key = ""  # the descriptions' key: a gesture is done once it is said
        self._identified: tuple[str, Message | None, Identity | None] = ("", None, None)
        # said() as of (book version, said_key)
        self._said: tuple[int, str, frozenset[int]] = (-1, "", frozenset())

    async def ask(self, bus: Bus, log: logging.Logger, *, restarted: bool = False) -> None:
        """What the others know (their ledgers, and the copies they kept of everyone's, this
        service's predecessor's among them): called before the service opens its streams.
        `restarted` (its supervisor says so): ask until the predecessor's record is among the
        answers, for at most ASK_TIMEOUT_S; it is somewhere unless the predecessor died before
        its first ledger went out."""
        began = time.monotonic()
        if self.file is not None:  # this machine's records outlive a deployment killed whole
            for kept in self.file.siblings():
                self.book.heard(kept, alive=False)
                if kept.service == self.name:
                    self.kept.merge(kept.handled)
        while True:
            left = ASK_TIMEOUT_S - (time.monotonic() - began)
            with contextlib.suppress(InputError, TimeoutError):  # a malformed one: no ledgers
                replies = await bus.query(
                    bus.keys.ledger(), Ledger, timeout=max(left, ASK_AGAIN_S), every=True
                )
                for reply in replies:
                    self.book.heard(reply.message)
            if not restarted or self.name in self.book.handled or left <= ASK_AGAIN_S:
                break
            await asyncio.sleep(ASK_AGAIN_S)
        self.instance = self.book.instance_of(self.name) + 1
        took = round(time.monotonic() - began, 3)
        if self.name in self.book.handled:
            event(log, logging.INFO, "resuming after a previous instance", asked_s=took)
        elif restarted:
            event(log, logging.WARNING, "restarted, but no service kept a record of the "
                  "previous instance: starting afresh", asked_s=took)  # fmt: skip

    def keep_on_disk(self, file: LedgerFile) -> None:
        """Keep this ledger in `file` too, going on from the one found there (for a consumer
        that asks no one: a monitor)."""
        self.file = file
        for kept in file.siblings():
            if kept.service == self.name:
                self.kept.merge(kept.handled)
                self.instance = max(self.instance, kept.instance + 1)

    def predecessor(self) -> dict[str, int]:
        """The numbers the previous instance of this service left to resume from ({} if none)."""
        return self.book.resume_of(self.name)

    def adopt(self, keys: Iterable[str], outputs: Iterable[str] = ()) -> None:
        """Take the predecessor's handled identities on `keys`: not to act on them again;
        with identified `outputs`, only for the gestures whose results on every one of them
        reached every consumer (a result that died with a consumer is made again)."""
        before = self.book.handled.get(self.name)
        if before is None:
            return
        taken = Handled()
        taken.merge(before.wire(), keys)
        for key in outputs:
            delivered = self.book.delivered(key, self.name)
            if delivered is None:
                continue
            for kinds in taken.keys.values():
                for segments in kinds.values():
                    for segment in [s for s in segments if s not in delivered]:
                        del segments[segment]
        self.handled.merge(taken.wire())

    def open(
        self, bus: Bus, on_error: Callable[[str, Exception], None]
    ) -> Coroutine[Any, Any, None]:
        """Publish this service's ledger, answer for everyone's, and keep hearing the others';
        returns the coroutine to run beside the handlers."""
        self.announce(bus)

        async def answer(_key: str, _request: None) -> list[tuple[str, Message]]:
            mine = self.ledger()
            others = [m for n, m in self.book.last.items() if n != self.name]
            return [(bus.keys.ledger(m.service), m) for m in [mine, *others]]

        bus.queryable(bus.keys.ledger(), None, answer, on_error=on_error)
        sub = bus.subscribe(bus.keys.ledger(), Ledger, STATUS)

        def heard(msg: Ledger) -> None:
            if msg.service != self.name:
                self.book.heard(msg)

        return consume(sub, heard, on_error)

    def announce(self, bus: Bus) -> None:
        """Publish this ledger from now on (`publish`, `tick`): all a consumer that serves and
        resumes nothing needs (a monitor), since every service keeps and answers for it."""
        self._pub = bus.publisher(bus.keys.ledger(self.name), Ledger, STATUS)
        self.publish()

    def ledger(self) -> Ledger:
        return Ledger(
            header=self._header(Ledger, None),
            service=self.name,
            instance=self.instance,
            handled=self.handled.wire(),
            resume=dict(self.resume),
            resume_stamps=dict(self.resume_stamps),
            positions=on_the_wire(self.positions),
        )

    def publish(self) -> None:
        self._dirty = False
        if self._pub is not None or self.file is not None:
            ledger = self.ledger()
            if self.file is not None:  # with what its predecessors handled: it is all done
                self.kept.merge(ledger.handled)
                self.file.save(msgspec.structs.replace(ledger, handled=self.kept.wire()))
            if self._pub is not None:
                self._pub.put(ledger)

    def tick(self) -> None:
        """With health: publish what changed since (per-frame entries, a new checkpoint)."""
        if self._dirty:
            self.publish()

    def checkpoint(
        self,
        stamps: Mapping[str, int],
        counts: Mapping[str, int] | None = None,
        positions: Mapping[Position, int] | None = None,
    ) -> None:
        """Where a next instance would resume, its stamps and counts (`predecessor` gives both
        back as one mapping), and per sensor key the first stamp it needs (`positions`)."""
        counts, at = dict(counts or {}), dict(positions or {})
        if dict(stamps) != self.resume_stamps or counts != self.resume or at != self.positions:
            self.resume_stamps, self.resume, self.positions = dict(stamps), counts, at
            self._dirty = True

    # -- the checks -------------------------------------------------------------------------

    def _identify(self, key: str, message: Message) -> Identity | None:
        """`identify`, once per message: a message is checked (`duplicate`) before its handler
        and recorded (`record`) after it."""
        last_key, last_message, ident = self._identified
        if message is not last_message or key != last_key:
            ident = identify(key, message)
            self._identified = (key, message, ident)
        return ident

    def duplicate(self, key: str, message: Message) -> Identity | None:
        """The identity of a message already handled on `key` (counted), else None."""
        ident = self._identify(key, message)
        if ident is not None and self.handled.has(key, ident):
            self.duplicates += 1
            return ident
        return None

    def record(self, key: str, message: Message) -> bool:
        """`message` on `key` has been handled (a per-gesture one is told at once): whether
        it is new (False: handled already, or it has no identity)."""
        ident = self._identify(key, message)
        if ident is None or not self.handled.add(key, ident):
            return False
        if ident.per_gesture:
            self.publish()
        else:
            self._dirty = True
        return True

    def seen_downstream(self, key: str, kinds: Iterable[str]) -> set[int]:
        """Segment ids some consumer of `key` has handled with one of `kinds`: where a
        restarted producer that cannot rebuild its state exactly numbers on, and what it must
        close."""
        return {
            segment for n, h in self.book.handled.items() if n != self.name
            for kind in kinds for segment in h.segments(key, kind)
        }  # fmt: skip

    def unsaid(self, said_key: str, gestures: Iterable[int]) -> list[int]:
        """Of `gestures`, oldest first, those some service taking `said_key` (the
        descriptions) has not handled: after a takeover their outputs may have died with the
        workstation, so a successor goes back to a checkpoint before the oldest ([] when
        nobody takes the descriptions: nothing to go back for)."""
        if not self.book.taken(said_key, self.name):
            return []
        said = self.book.done(said_key, "description", self.name)
        return sorted(n for n in gestures if n not in said)

    def done_downstream(self, key: str, kind: str) -> set[int]:
        """Segments whose `kind` every consumer of this service's `key` has handled and whose
        description every consumer of descriptions has (`said_key`): a restarted service need
        not work on them again. One not said yet is derived again (its description died with
        a consumer: the whole deployment was killed)."""
        done = self.book.done(key, kind, self.name)
        if self.said_key and self.book.taken(self.said_key, self.name):
            done &= self.book.done(self.said_key, "description", self.name)
        return done

    def suppressed(self, key: str, message: Message) -> bool:
        """Every consumer of `key` has handled `message` already, and its gesture is said: do
        not send it again. A consumer's ledger can be ahead of what outlives it: killed at the
        same moment as this producer, its successor (not heard of yet) has nothing of a
        gesture under way and needs all of it again, from this producer's cache. Only a
        gesture whose description every consumer of descriptions has is beyond that (nothing
        is withheld when nobody takes descriptions). A gesture's start, end or cancel is always
        sent (two a gesture): a consumer cannot rebuild without them."""
        said = self.said()
        if not said or not self.book.taken(key, self.name):
            return False
        ident = identify(key, message)
        if ident is None or ident.kind in SEGMENT_EVENTS or ident.segment_id not in said:
            return False
        return self.book.consumers_have(key, ident, self.name)

    def said(self) -> frozenset[int]:
        """Gestures whose description every consumer of descriptions has handled (in any of its
        instances: a sentence said, a line printed, is kept by their own records). Asked before
        every put, it is worked out again only when a ledger has been heard since."""
        version, key, said = self._said
        if version != self.book.version or key != self.said_key:
            said = frozenset()
            if self.said_key and self.book.taken(self.said_key, self.name):
                said = frozenset(self.book.done(self.said_key, "description", self.name))
            self._said = (self.book.version, self.said_key, said)
        return said
