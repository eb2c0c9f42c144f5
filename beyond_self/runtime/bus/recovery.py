"""Streams that survive a broken link: the subscriber half (zenoh-ext advanced subscriber).

Wi-Fi drops and cables are pulled; what is published meanwhile goes nowhere, and a lost "end"
event means a gesture never described. So derived streams' publishers keep a cache
(runtime.bus.publisher) and their subscribers here ask every publisher for its history and recover
gaps from it: delivered in order per publisher, each once, what no cache holds counted as
`missed`. A plain subscriber beside it witnesses the live samples, so a delivered one it never
saw is counted as `recovered`; it reads a ring channel, not a callback, to spare Zenoh's thread
the GIL (docs/decisions.md). runtime.bus.history_repair covers a zenoh-ext 1.10 history bug.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import OrderedDict, deque

import zenoh
from zenoh import ext

from beyond_self.runtime.bus.delivery import Delivery
from beyond_self.runtime.bus.history_repair import HistoryRepair
from beyond_self.runtime.bus.inbox import Inbox, direct_callback, undeclare

log = logging.getLogger("beyond.recovery")

HEARTBEAT_S = 0.5  # publishers' periodic heartbeat: the last sequence number (droppable)
_WITNESS_GRACE_S = 1.0  # a delivered sample not witnessed live within this is a recovered one
_WITNESS_MEMORY = 16384  # live (source, sn) pairs remembered for that comparison
# Live samples waiting to be read; reads come with every delivery, so more wait only while the
# advanced subscriber holds deliveries back. 128 is 4 s of a 30 Hz stream, longer than the grace:
# a sample held back that long counts as recovered either way. Every slot the ring has cycled
# through stays resident (1,024 cost a 64-robot streamer 68 MB).
_WITNESS_CHANNEL = 128


class RecoveringSource:
    """Feeds `inbox` with (key, payload, received_ns) from an advanced subscriber on `key`."""

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        inbox: Inbox[tuple[str, bytes | zenoh.ZBytes, int]],
        delivery: Delivery,
    ) -> None:
        self.missed = 0
        self._lock = threading.Lock()
        self._live: OrderedDict[tuple[str, int], None] = OrderedDict()
        self._unconfirmed: deque[tuple[tuple[str, int], float]] = deque()
        self._recovered = 0
        self._closed = False
        push = inbox.push

        def deliver(sample: zenoh.Sample) -> None:  # Zenoh thread (or the repair's)
            info = sample.source_info
            if info is not None:
                self._delivered((str(info.source_id), int(info.source_sn)))
            push((str(sample.key_expr), sample.payload.to_bytes(), time.time_ns()))

        def missed(count: int) -> None:
            self.missed += count

        repair = HistoryRepair(session, key, delivery, deliver, missed)

        def on_miss(miss: ext.Miss) -> None:  # Zenoh thread
            self.missed += int(miss.nb)
            log.warning(
                "%d samples on %s lost for good (no longer in the publisher's cache)", miss.nb, key
            )

        self._witness = session.declare_subscriber(
            key, zenoh.handlers.RingChannel(_WITNESS_CHANNEL)
        )
        self._sub = ext.declare_advanced_subscriber(
            session,
            key,
            direct_callback(repair.offer),
            history=ext.HistoryConfig(
                detect_late_publishers=True,
                max_samples=delivery.history,
                max_age=delivery.max_age_s,
            ),
            recovery=ext.RecoveryConfig(periodic_queries=None, heartbeat=True),
        )
        self._miss_listener = self._sub.sample_miss_listener(direct_callback(on_miss))

    def _delivered(self, ident: tuple[str, int]) -> None:
        with self._lock:
            self._unconfirmed.append((ident, time.monotonic()))
            self._settle(time.monotonic())

    def _witnessed(self) -> None:  # with the lock held
        """Remember the live samples the witness has seen since last asked."""
        if self._closed:
            return  # an undeclared subscriber's channel raises
        live, take = self._live, self._witness.try_recv
        while (sample := take()) is not None:
            info = sample.source_info
            if info is None:
                continue
            live[(str(info.source_id), int(info.source_sn))] = None
            if len(live) > _WITNESS_MEMORY:
                live.popitem(last=False)

    def _settle(self, now: float) -> None:  # with the lock held
        self._witnessed()
        pending, live = self._unconfirmed, self._live
        while pending:
            ident, at = pending[0]
            if ident in live:
                del live[ident]
            elif now - at < _WITNESS_GRACE_S:
                return
            else:
                self._recovered += 1
            pending.popleft()

    @property
    def recovered(self) -> int:
        """Samples delivered from a publisher cache (history or gap recovery), so far."""
        with self._lock:
            self._settle(time.monotonic())
            return self._recovered

    def close(self) -> None:
        with self._lock:
            self._witnessed()  # what it saw still counts
            self._closed = True
        for entity in (self._miss_listener, self._sub, self._witness):
            undeclare(entity)
