"""Streams that survive a broken link: publisher caches and subscriber recovery (zenoh-ext).

Between a robot and a workstation the network does fail: Wi-Fi drops, a cable is pulled, a
router restarts. Zenoh then closes the session when its lease runs out and re-opens it when the
link is back; whatever was published in between went nowhere. For derived streams (gesture
posteriors and events, detected objects, effects, words, descriptions) every message matters: a
gesture whose "end" event is lost is never described. So those streams use zenoh-ext:

- `ReliablePublisher`: an `AdvancedPublisher` that keeps the last `cache` samples, numbers them
  (sample miss detection), sends a sporadic heartbeat with the last number, and declares itself
  with a liveliness token (publisher detection).
- `ReliableSubscription`: an `AdvancedSubscriber` that asks every publisher it detects for its
  history (also when a publisher comes back after a partition) and recovers gaps it sees in the
  numbering or in the heartbeats from that publisher's cache. Samples are delivered in order per
  publisher, each once; what a cache no longer holds is counted in `missed` and logged.

It also counts what came back from a cache rather than off the wire (`recovered`): a plain
subscriber on the same key in the same session witnesses every live sample, so a delivered
(source, sequence number) the witness never saw can only be a recovered one. Deployments say
how much the caches saved, and the distributed test checks it.

Raw sensor streams (skeleton, camera) stay plain: large, and stale sensor data is useless.
Sequence numbers need no clock; `max_age_s` (history by age) uses sample timestamps, which a
session adds only with `timestamping` enabled (as in `deploy/zenoh/*.json5`); without them the
history is bounded by count alone.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import zenoh
from zenoh import ext

from core.errors import InputError
from runtime.bus import DecodedStream, Inbox
from schemas.base import Message
from schemas.codec import SchemaError, encode, wire_encoding

M = TypeVar("M", bound=Message)
log = logging.getLogger("beyond.reliable")

DEFAULT_CACHE = 1024  # samples per publisher: ~30 s of a per-frame stream at 30 Hz
FRAME_CACHE = DEFAULT_CACHE  # per-frame derived streams (posteriors, objects, predictions)
EVENT_CACHE = 64  # per-gesture streams (segment events, effects, words, descriptions)
HEARTBEAT_S = 0.5  # sporadic heartbeat: the last sequence number, only when it changed
_WITNESS_GRACE_S = 1.0  # a delivered sample not witnessed live within this is a recovered one
_WITNESS_MEMORY = 16384  # live (source, sn) pairs remembered for that comparison


@dataclass(frozen=True)
class RecoveryPolicy:
    """What a subscriber asks of the publishers it (re)discovers."""

    history: int = DEFAULT_CACHE  # samples asked of each publisher when it appears
    max_age_s: float | None = None  # and none older than this (needs session timestamping)

    def __post_init__(self) -> None:
        if self.history < 1:
            raise InputError(f"history of {self.history} samples; valid: at least 1")
        if self.max_age_s is not None and self.max_age_s <= 0:
            raise InputError(f"history age {self.max_age_s} s; valid: > 0 or None")


def _handler(fn: Callable[[Any], None]) -> Any:
    """Run `fn` on the Zenoh thread itself (it only appends to a deque)."""
    try:
        return zenoh.handlers.Callback(fn, indirect=False)
    except TypeError:  # older zenoh-python without `indirect`
        return fn


class ReliablePublisher(Generic[M]):
    """Publishes messages of one type on one key, with a cache subscribers recover from.
    Same interface as `runtime.bus.Publisher` (`put`, `put_bytes`, `sent`, `close`).

    It never blocks (congestion control DROP) unless `block`: the cache is what makes the stream
    reliable. A dead link that Zenoh has not given up on yet fills its queue within seconds; a
    blocking put would then stall the robot's own pipeline (the gesture streamer stops reading
    skeleton frames) until the lease runs out. Dropped samples leave a gap in the sequence
    numbers that subscribers fill from the cache."""

    def __init__(
        self,
        session: Any,
        key: str,
        cls: type[M],
        *,
        cache: int = DEFAULT_CACHE,
        block: bool = False,
        heartbeat_s: float = HEARTBEAT_S,
    ) -> None:
        if cache < 1:
            raise InputError(f"publisher cache of {cache} samples; valid: at least 1")
        if heartbeat_s <= 0:
            raise InputError(f"heartbeat period {heartbeat_s} s; valid: > 0")
        self.key = key
        self.cls = cls
        self.cache = cache
        self.sent = 0
        self.last_stamp = -1  # of the last message sent
        self.skip_until = -1  # messages stamped at or before this are not sent (a restart)
        self.suppressed = 0
        congestion = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
        self._pub = ext.declare_advanced_publisher(
            session,
            key,
            encoding=zenoh.Encoding(wire_encoding(cls)),
            congestion_control=congestion,
            # replies (recovery) keep zenoh's default: blocking, they are what must get through
            cache=ext.CacheConfig(cache),
            sample_miss_detection=ext.MissDetectionConfig(
                heartbeat=None, sporadic_heartbeat=heartbeat_s
            ),
            publisher_detection=True,
        )

    def put(self, message: M) -> None:
        if type(message) is not self.cls:
            raise TypeError(f"publisher of {self.cls.__name__} got {type(message).__name__}")
        stamp = message.header.stamp
        if stamp <= self.skip_until:
            self.suppressed += 1  # a previous instance of this service already published it
            return
        self.last_stamp = stamp
        self._pub.put(encode(message))
        self.sent += 1

    def put_bytes(self, payload: bytes) -> None:
        """Publish an already encoded payload (replay)."""
        self._pub.put(payload)
        self.sent += 1

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self._pub.undeclare()


class ReliableSubscription(DecodedStream[M]):
    """Decoded messages of one type on a key, recovered across link failures. Same interface as
    `runtime.bus.Subscription` (`recv`, async iteration, `received`, `malformed`, `dropped`,
    `close`), plus `recovered` (samples that came from a publisher cache, not off the wire) and
    `missed` (samples no cache could give back any more)."""

    def __init__(
        self,
        session: Any,
        key: str,
        cls: type[M],
        loop: asyncio.AbstractEventLoop,
        maxsize: int = 1024,
        on_malformed: Callable[[str, SchemaError], None] | None = None,
        policy: RecoveryPolicy | None = None,
    ) -> None:
        policy = policy or RecoveryPolicy()
        self.key = key
        self.cls = cls
        self.policy = policy
        self.malformed = 0
        self.received = 0
        self.missed = 0
        self._on_malformed = on_malformed
        self._inbox: Inbox[tuple[str, bytes, int]] = Inbox(loop, maxsize)
        self._lock = threading.Lock()
        self._live: OrderedDict[tuple[str, int], None] = OrderedDict()
        self._unconfirmed: deque[tuple[tuple[str, int], float]] = deque()
        self._recovered = 0
        push = self._inbox.push

        def on_sample(sample: Any) -> None:  # Zenoh thread
            info = sample.source_info
            if info is not None:
                self._delivered((str(info.source_id), int(info.source_sn)))
            push((str(sample.key_expr), sample.payload.to_bytes(), time.time_ns()))

        def on_live(sample: Any) -> None:  # Zenoh thread: the witness
            info = sample.source_info
            if info is None:
                return
            with self._lock:
                live = self._live
                live[(str(info.source_id), int(info.source_sn))] = None
                if len(live) > _WITNESS_MEMORY:
                    live.popitem(last=False)

        def on_miss(miss: Any) -> None:  # Zenoh thread
            self.missed += int(miss.nb)
            log.warning(
                "%d samples on %s lost for good (no longer in the publisher's cache)", miss.nb, key
            )

        self._witness = session.declare_subscriber(key, _handler(on_live))
        self._sub = ext.declare_advanced_subscriber(
            session,
            key,
            _handler(on_sample),
            history=ext.HistoryConfig(
                detect_late_publishers=True, max_samples=policy.history, max_age=policy.max_age_s
            ),
            recovery=ext.RecoveryConfig(periodic_queries=None, heartbeat=True),
        )
        self._miss_listener = self._sub.sample_miss_listener(_handler(on_miss))

    # -- recovered-sample accounting -------------------------------------------------------

    def _delivered(self, ident: tuple[str, int]) -> None:
        with self._lock:
            self._unconfirmed.append((ident, time.monotonic()))
            self._settle(time.monotonic())

    def _settle(self, now: float) -> None:  # with the lock held
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
        if not self._inbox.closed:
            for entity in (self._miss_listener, self._sub, self._witness):
                with contextlib.suppress(Exception):
                    entity.undeclare()
            self._inbox.close()


def reliable_publisher(
    bus: Any, key: str, cls: type[M], *, cache: int = DEFAULT_CACHE, block: bool = False
) -> ReliablePublisher[M]:
    """A cached publisher on `bus`'s session, closed with the bus."""
    pub = ReliablePublisher(bus.session, key, cls, cache=cache, block=block)
    _on_close(bus, pub.close)
    return pub


def reliable_subscription(
    bus: Any,
    key: str,
    cls: type[M],
    *,
    maxsize: int = 1024,
    on_malformed: Callable[[str, SchemaError], None] | None = None,
    policy: RecoveryPolicy | None = None,
) -> ReliableSubscription[M]:
    """A recovering subscription on `bus`'s session (call from the consuming event loop),
    closed with the bus."""
    sub = ReliableSubscription(
        bus.session, key, cls, asyncio.get_running_loop(), maxsize, on_malformed, policy
    )
    _on_close(bus, sub.close)
    return sub


def _on_close(bus: Any, closer: Callable[[], None]) -> None:
    closers = getattr(bus, "_closers", None)  # runtime.bus.Bus closes these before the session
    if isinstance(closers, list):
        closers.append(closer)
