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
from collections import Counter, OrderedDict, deque
from collections.abc import Callable
from typing import Any

import zenoh
from zenoh import ext

from beyond_self.runtime.bus.delivery import Delivery
from beyond_self.runtime.bus.history_repair import HistoryRepair
from beyond_self.runtime.bus.inbox import Inbox, direct_callback, undeclare
from beyond_self.schemas.keys import robot_of

log = logging.getLogger("beyond.recovery")

HEARTBEAT_S = 0.5  # publishers' periodic heartbeat: the last sequence number (droppable)
_WITNESS_GRACE_S = 1.0  # a delivered sample not witnessed live within this is a recovered one
_WITNESS_MEMORY = 16384  # live (source, sn) pairs remembered for that comparison
# Live samples waiting to be read; reads come with every delivery, so more wait only while the
# advanced subscriber holds deliveries back. 128 is 4 s of a 30 Hz stream, longer than the grace:
# a sample held back that long counts as recovered either way. Every slot the ring has cycled
# through stays resident (1,024 cost a 64-robot streamer 68 MB).
_WITNESS_CHANNEL = 128
# A fleet process's one subscriber for every robot (runtime.bus.demux): zenoh-ext hands it the
# history of every publisher at once, on the declaring thread, before its drain thread can start;
# a bounded channel that history overfills would block that thread for ever. Zenoh's FIFO channel
# allocates as it fills, so this bound costs nothing until used: a thousand robots' full skeleton
# caches (1,024 frames each) at the declaration. The witness sees every robot.
_SHARED_CHANNEL = 1 << 20
_SHARED_WITNESS = 4096
_BURST = 256  # samples taken with the GIL held once at most


class RecoveringSource:
    """Feeds `inbox` with (key, payload, received_ns) from an advanced subscriber on `key`.

    Per run (`shared` False) zenoh-ext's callback delivers, on Zenoh's thread. `shared` (a fleet
    process's one subscriber for a stream of every robot, runtime.bus.demux) reads a channel
    on a drain thread instead, a burst per taking of the GIL, and counts what was recovered and
    missed per robot (`recovered_of`, `missed_of`)."""

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        inbox: Inbox[tuple[str, bytes | zenoh.ZBytes, int]],
        delivery: Delivery,
        *,
        shared: bool = False,
    ) -> None:
        self.missed = 0
        self._lock = threading.Lock()
        self._live: OrderedDict[tuple[str, int], None] = OrderedDict()
        self._unconfirmed: deque[tuple[tuple[str, int], float, str]] = deque()
        self._recovered = 0
        self._recovered_by: Counter[str] = Counter()  # robot -> recovered (shared only)
        self._missed_by: Counter[str] = Counter()  # robot -> missed (shared only)
        self._source_robot: OrderedDict[str, str] = OrderedDict()  # publisher -> its robot
        self._closed = False
        self._shared = shared
        burst: list[tuple[str, bytes | zenoh.ZBytes, int]] = []
        drainer: list[int] = []  # the drain thread's ident, once it runs
        push = inbox.push

        def deliver(sample: zenoh.Sample) -> None:  # Zenoh's, the drain's or the repair's thread
            key_ = str(sample.key_expr)
            robot = robot_of(key_) if shared else ""
            info = sample.source_info
            if info is not None:
                source = str(info.source_id)
                if shared and source not in self._source_robot:
                    self._learn(source, robot)
                self._delivered((source, int(info.source_sn)), robot)
            item = (key_, sample.payload.to_bytes(), time.time_ns())
            if drainer and drainer[0] == threading.get_ident():
                burst.append(item)  # handed over with the rest of the burst
            else:
                push(item)

        def missed(count: int, key_: str) -> None:
            self.missed += count
            if shared:
                self._missed_by[robot_of(key_)] += count

        repair = HistoryRepair(session, key, delivery, deliver, missed)

        def on_miss(miss: ext.Miss) -> None:  # Zenoh thread
            self.missed += int(miss.nb)
            if shared:
                self._missed_by[self._source_robot.get(str(miss.source), "")] += int(miss.nb)
            log.warning(
                "%d samples on %s lost for good (no longer in the publisher's cache)", miss.nb, key
            )

        self._witness = session.declare_subscriber(
            key, zenoh.handlers.RingChannel(_SHARED_WITNESS if shared else _WITNESS_CHANNEL)
        )
        history = ext.HistoryConfig(
            detect_late_publishers=True, max_samples=delivery.history, max_age=delivery.max_age_s
        )
        recovery = ext.RecoveryConfig(periodic_queries=None, heartbeat=True)
        if not shared:
            self._sub: ext.AdvancedSubscriber[Any] = ext.declare_advanced_subscriber(
                session, key, direct_callback(repair.offer), history=history, recovery=recovery
            )
        else:
            channel = ext.declare_advanced_subscriber(
                session,
                key,
                zenoh.handlers.FifoChannel(_SHARED_CHANNEL),
                history=history,
                recovery=recovery,
            )
            self._sub = channel

            def flush() -> None:
                with self._lock:
                    self._settle(time.monotonic())
                inbox.extend(burst)
                burst.clear()

            def drain() -> None:
                drainer.append(threading.get_ident())
                _drain(channel.handler, repair.offer, flush)

            threading.Thread(target=drain, name=f"zenoh-drain {key}", daemon=True).start()
        self._miss_listener = self._sub.sample_miss_listener(direct_callback(on_miss))

    def _learn(self, source: str, robot: str) -> None:
        self._source_robot[source] = robot
        while len(self._source_robot) > _WITNESS_MEMORY:
            self._source_robot.popitem(last=False)

    def _delivered(self, ident: tuple[str, int], robot: str) -> None:
        with self._lock:
            self._unconfirmed.append((ident, time.monotonic(), robot))
            if not self._shared:  # shared: settled once per burst
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
            ident, at, robot = pending[0]
            if ident in live:
                del live[ident]
            elif now - at < _WITNESS_GRACE_S:
                return
            else:
                self._recovered += 1
                if self._shared:
                    self._recovered_by[robot] += 1
            pending.popleft()

    @property
    def recovered(self) -> int:
        """Samples delivered from a publisher cache (history or gap recovery), so far."""
        with self._lock:
            self._settle(time.monotonic())
            return self._recovered

    def recovered_of(self, robot: str) -> int:
        """`recovered`, of robot `robot`'s samples only (a shared source)."""
        with self._lock:
            self._settle(time.monotonic())
            return self._recovered_by[robot]

    def missed_of(self, robot: str) -> int:
        """`missed`, of robot `robot`'s samples only (a shared source)."""
        return self._missed_by[robot]

    def close(self) -> None:
        with self._lock:
            self._witnessed()  # what it saw still counts
            self._closed = True
        for entity in (self._miss_listener, self._sub, self._witness):
            undeclare(entity)


def _drain(
    handler: zenoh.handlers.Handler[zenoh.Sample],
    offer: Callable[[zenoh.Sample], None],
    flush: Callable[[], None],
) -> None:
    """Body of a shared recovering source's drain thread: every sample the advanced subscriber
    delivers, in its order, to `offer` (the history repair), then `flush` once per burst, until
    the subscriber is undeclared (then `recv` raises)."""
    recv, try_recv = handler.recv, handler.try_recv
    while True:
        try:
            sample: zenoh.Sample | None = recv()  # blocks with the GIL released
        except Exception:  # zenoh.ZError: channel closed, the subscriber is gone
            return
        taken = 0
        while sample is not None:
            offer(sample)
            taken += 1
            if taken >= _BURST:
                break
            try:
                sample = try_recv()
            except Exception:  # closed while draining a burst: what came is delivered
                sample = None
        flush()
