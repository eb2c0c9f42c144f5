"""Publishing messages of one type on one key, as a `Delivery` says (runtime.bus.delivery).

With `delivery.cache`, the publisher is a zenoh-ext advanced publisher that keeps its last `cache`
samples for subscribers that recover (runtime.bus.recovery), numbers them (sample miss
detection), sends a periodic heartbeat with the last number, and declares itself with a liveliness
token (publisher detection). Without, it is a plain Zenoh publisher.

With `suppress` set (the Service base sets it, runtime.resilience.ledger), `put` skips, and
counts, a message every consumer of the key has handled: a restarted service says nothing twice.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Callable
from typing import Generic, TypeVar

import zenoh
from zenoh import ext

from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.delivery import RELIABLE, Delivery
from beyond_self.runtime.bus.inbox import Inbox, direct_callback, undeclare
from beyond_self.runtime.bus.recovery import HEARTBEAT_S
from beyond_self.schemas.base import Message
from beyond_self.schemas.codec import encode, encode_into, wire_encoding

M = TypeVar("M", bound=Message)
ZenohPublisher = zenoh.Publisher | ext.AdvancedPublisher


def congestion_control(delivery: Delivery) -> zenoh.CongestionControl:
    if delivery.congestion == "block":
        return zenoh.CongestionControl.BLOCK
    return zenoh.CongestionControl.DROP


def declare_zenoh_publisher(
    session: zenoh.Session, key: str, encoding: str | None, delivery: Delivery
) -> ZenohPublisher:
    """The Zenoh publisher `delivery` asks for, plain or advanced (cached)."""
    zencoding = zenoh.Encoding(encoding) if encoding else None
    if not delivery.cache:
        return session.declare_publisher(
            key,
            encoding=zencoding,
            congestion_control=congestion_control(delivery),
            express=delivery.express,
        )
    return ext.declare_advanced_publisher(
        session,
        key,
        encoding=zencoding,
        congestion_control=congestion_control(delivery),
        express=delivery.express,
        # replies (recovery) keep zenoh's default: blocking, they are what must get through
        cache=ext.CacheConfig(delivery.cache),
        # A periodic heartbeat, not zenoh-ext's sporadic one: the sporadic heartbeat is sent
        # with congestion control BLOCK (it is sent once per change, so it must not be lost).
        # Across a dead link a router's queue fills, and a router forwarding a BLOCK message
        # waits on it with its receiving thread: every stream through that router stalls, the
        # local sessions' leases run out, and the dead transport, closed late, takes the new
        # one to the same router with it (zenoh 1.10). The periodic one repeats the last number
        # every period, so it may be dropped like the samples it announces.
        sample_miss_detection=ext.MissDetectionConfig(
            heartbeat=HEARTBEAT_S, sporadic_heartbeat=None
        ),
        publisher_detection=True,
    )


class Publisher(Generic[M]):
    def __init__(
        self, session: zenoh.Session, key: str, cls: type[M], delivery: Delivery = RELIABLE
    ) -> None:
        self.key = key
        self.cls = cls
        self.delivery = delivery
        self.sent = 0
        self.last_stamp = -1  # of the last message sent
        self.suppress: Callable[[str, Message], bool] | None = None  # consumers have it already
        self.suppressed = 0
        self.after_put: Callable[[], None] | None = None  # called after every put
        # written to before each put (the source's log, runtime.resilience.source_log): key, stamp,
        # payload
        self.tap: Callable[[str, int, bytes], None] | None = None
        self._owner = threading.get_ident()
        # One buffer reused for every put (Zenoh copies it before `put` returns): no fresh block
        # per message, which for camera frames costs more than encoding them. A cache keeps
        # the sample itself, so a cached publisher encodes into a fresh one.
        self._reuse = not delivery.cache
        self._buffer = bytearray()
        self._pub = declare_zenoh_publisher(session, key, wire_encoding(cls), delivery)

    def put(self, message: M) -> None:
        if type(message) is not self.cls:
            raise TypeError(f"publisher of {self.cls.__name__} got {type(message).__name__}")
        if self.suppress is not None and self.suppress(self.key, message):
            self.suppressed += 1  # handled by every consumer, sent by a previous instance
            if self.after_put is not None:
                self.after_put()
            return
        self.last_stamp = message.header.stamp
        if self.tap is not None:
            payload = encode(message)
            self.tap(self.key, self.last_stamp, payload)
            self._pub.put(payload)
        elif self._reuse and threading.get_ident() == self._owner:
            buffer = self._buffer
            encode_into(message, buffer)
            self._pub.put(buffer)
        else:  # another thread must not share the buffer
            self._pub.put(encode(message))
        self.sent += 1
        if self.after_put is not None:  # the owner tells its progress (Service.publisher)
            self.after_put()

    def put_bytes(self, payload: bytes) -> None:
        """Publish an already encoded payload (replay, benchmarks)."""
        self._pub.put(payload)
        self.sent += 1

    def _plain(self) -> zenoh.Publisher:
        if not isinstance(self._pub, zenoh.Publisher):
            raise InputError(
                f"the publisher on {self.key} keeps a cache (Delivery.cache), and zenoh-ext's "
                "cached publishers do not report matching subscribers; use a plain one"
            )
        return self._pub

    def matching(self) -> bool:
        """Whether any subscriber currently matches this key (plain publishers only)."""
        # zenoh's stub says bool; it is a MatchingStatus
        status: zenoh.MatchingStatus = self._plain().matching_status  # type: ignore[assignment]
        return bool(status.matching)

    def watch_matching(self, on_change: Callable[[bool], None]) -> Callable[[], None]:
        """`on_change(matching)` on a Zenoh thread whenever subscribers come or all go (plain
        publishers only); the call that stops it."""

        def changed(status: zenoh.MatchingStatus) -> None:
            on_change(bool(status.matching))

        listener = self._plain().declare_matching_listener(direct_callback(changed))
        return lambda: undeclare(listener)

    async def wait_matching(self, timeout: float = 5.0) -> None:
        """Wait until a subscriber matches (discovery handshake, not a fixed sleep)."""
        loop = asyncio.get_running_loop()
        inbox: Inbox[bool] = Inbox(loop, 16)

        def on_status(status: zenoh.MatchingStatus) -> None:
            inbox.push(bool(status.matching))

        listener = self._plain().declare_matching_listener(direct_callback(on_status))
        try:
            deadline = loop.time() + timeout
            while not self.matching():
                remaining = deadline - loop.time()
                if remaining <= 0:
                    raise TimeoutError(f"no subscriber for {self.key} within {timeout} s")
                with contextlib.suppress(TimeoutError):
                    await inbox.get(min(remaining, 0.5))
        finally:
            undeclare(listener)

    def close(self) -> None:
        undeclare(self._pub)
