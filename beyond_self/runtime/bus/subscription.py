"""Typed and raw subscriptions: samples off Zenoh, into an inbox, decoded on the event loop.

A subscription receives through a Zenoh FIFO channel, not a Python callback, so Zenoh's network
thread never takes the GIL (a callback there makes a Python thread state per sample: 3x fewer
samples per second). One drain thread per subscription blocks in `recv()` with the GIL released
and hands each burst to the inbox (runtime.bus.inbox); a recovering delivery uses a zenoh-ext
advanced subscriber and a drain thread of its own instead (runtime.bus.recovery). Decoding happens
on the event loop when the consumer takes the sample, so no Zenoh thread runs user code; a
consumer takes every sample ready with one wake-up (`consume`, `Subscription.ready`).
bench/bus.py measures it against raw zenoh-python.
"""

from __future__ import annotations

import asyncio
import inspect
import threading
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass
from typing import Generic, Protocol, TypeVar

import msgspec
import zenoh

from beyond_self.runtime.bus.delivery import RELIABLE, Delivery
from beyond_self.runtime.bus.inbox import Inbox, undeclare
from beyond_self.runtime.bus.recovery import RecoveringSource
from beyond_self.schemas.base import Message
from beyond_self.schemas.codec import SchemaError, decode, type_from_encoding
from beyond_self.schemas.keys import type_for_key

M = TypeVar("M", bound=Message)
T = TypeVar("T")

MalformedHandler = Callable[[str, SchemaError], None]
# (key, payload, received_ns): a large payload stays Zenoh's ZBytes until the loop copies it
WirePayload = tuple[str, bytes | zenoh.ZBytes, int]
RawWire = tuple[str, bytes | zenoh.ZBytes, str, int]  # (key, payload, encoding, received_ns)

# Zenoh-side staging channel of a subscription. The inbox behind it is the real bound (drops
# oldest, counted); this one only has to absorb a burst while the drain thread waits for the GIL
# (when it is full, Zenoh's network thread waits, as it did for the GIL with a callback).
_CHANNEL_CAPACITY = 256
_BURST = 256  # samples handed to the inbox per wake-up at most


class SharedSource(Protocol):
    """A stream of every robot that feeds one robot's subscription (runtime.bus.demux)."""

    def attach(self, robot: str, inbox: Inbox[WirePayload]) -> None: ...
    def detach(self, robot: str, inbox: Inbox[WirePayload]) -> None: ...
    def recovered_of(self, robot: str) -> int: ...
    def missed_of(self, robot: str) -> int: ...


@dataclass(slots=True, frozen=True)
class RawSample:
    """A sample as it came off the wire."""

    key: str
    payload: bytes
    encoding: str
    received_ns: int  # wall clock (ns since epoch) when the sample was taken off Zenoh


class Received(msgspec.Struct, Generic[M], frozen=True, gc=False):
    """A decoded message and where/when it arrived. A msgspec struct, not a dataclass: one is
    made for every message, and a frozen dataclass's `__init__` costs ten times as much."""

    key: str
    message: M
    received_ns: int


def _drain(
    handler: zenoh.handlers.Handler[zenoh.Sample],
    inbox: Inbox[T],
    convert: Callable[[zenoh.Sample, int], T],
) -> None:
    """Body of a subscription's drain thread: channel -> inbox, a burst at a time, until the
    subscriber is undeclared (then `recv` raises)."""
    recv, try_recv, now = handler.recv, handler.try_recv, time.time_ns
    while True:
        try:
            sample = recv()  # blocks with the GIL released
        except Exception:  # zenoh.ZError: channel closed, the subscriber is gone
            return
        batch = [convert(sample, now())]
        while len(batch) < _BURST:
            try:
                more = try_recv()
            except Exception:  # closed while draining a burst: deliver what came, then leave
                more = None
            if more is None:
                break
            batch.append(convert(more, now()))
        inbox.extend(batch)


def _drain_typed(
    handler: zenoh.handlers.Handler[zenoh.Sample], inbox: Inbox[WirePayload], key: str
) -> None:
    """`_drain` for a typed subscription, its conversion inline (the hot path): (key, payload,
    received_ns), the key the subscription's own unless it is a wildcard, one clock reading
    per burst (its samples were all taken off Zenoh then)."""
    recv, try_recv, now = handler.recv, handler.try_recv, time.time_ns
    wildcard = "*" in key or "$" in key
    while True:
        try:
            sample: zenoh.Sample | None = recv()  # blocks with the GIL released
        except Exception:  # zenoh.ZError: channel closed, the subscriber is gone
            return
        at = now()
        batch: list[WirePayload] = []
        while sample is not None:
            payload = sample.payload
            batch.append(
                (
                    str(sample.key_expr) if wildcard else key,
                    payload.to_bytes() if len(payload) <= _COPY_ON_LOOP else payload,
                    at,
                )
            )
            if len(batch) >= _BURST:
                break
            try:
                sample = try_recv()
            except Exception:  # closed while draining a burst: deliver what came, then leave
                sample = None
        inbox.extend(batch)


def _channel_subscriber(
    session: zenoh.Session,
    key: str,
    inbox: Inbox[T],
    drain: Callable[[zenoh.handlers.Handler[zenoh.Sample]], None],
) -> zenoh.Subscriber[zenoh.handlers.Handler[zenoh.Sample]]:
    """Declare a subscriber on `key` whose samples reach `inbox` through a drain thread running
    `drain(channel)`."""
    sub = session.declare_subscriber(key, zenoh.handlers.FifoChannel(_CHANNEL_CAPACITY))
    thread = threading.Thread(
        target=drain, args=(sub.handler,), name=f"zenoh-drain {key}", daemon=True
    )
    thread.start()
    return sub


def typed_channel_subscriber(
    session: zenoh.Session, key: str, inbox: Inbox[WirePayload]
) -> zenoh.Subscriber[zenoh.handlers.Handler[zenoh.Sample]]:
    """A plain subscriber on `key` feeding a typed subscription's `inbox` (`_drain_typed`)."""

    def drain(handler: zenoh.handlers.Handler[zenoh.Sample]) -> None:
        _drain_typed(handler, inbox, key)

    return _channel_subscriber(session, key, inbox, drain)


# Payloads above Zenoh's batch size were reassembled into a buffer of their own, so keeping the
# sample pins nothing else; they are copied out on the loop, right before decoding reads them.
_COPY_ON_LOOP = 64 * 1024


def _wire_payload(sample: zenoh.Sample) -> bytes | zenoh.ZBytes:
    """The payload as bytes, or for a large one still as Zenoh's ZBytes (`_COPY_ON_LOOP`)."""
    payload = sample.payload
    return payload.to_bytes() if len(payload) <= _COPY_ON_LOOP else payload


def _raw_wire(sample: zenoh.Sample, received_ns: int) -> RawWire:
    """Drain-thread conversion for a raw subscription; `RawSubscription.recv` makes the
    RawSample."""
    return (str(sample.key_expr), _wire_payload(sample), str(sample.encoding), received_ns)


async def _until_closed(recv: Callable[[], Awaitable[T]]) -> AsyncIterator[T]:
    """What `recv()` returns, one after the other, until the inbox is closed and drained."""
    while True:
        try:
            yield await recv()
        except EOFError:
            return


class RawSubscription:
    """Undecoded samples of one or more key expressions (recorder, echo): in arrival order per
    key expression (each has its own Zenoh subscriber)."""

    def __init__(
        self, session: zenoh.Session, keys: list[str], loop: asyncio.AbstractEventLoop, maxsize: int
    ) -> None:
        self.keys = keys
        self._inbox: Inbox[RawWire] = Inbox(loop, maxsize, wakeup_fd=True)
        inbox = self._inbox

        def drain(handler: zenoh.handlers.Handler[zenoh.Sample]) -> None:
            _drain(handler, inbox, _raw_wire)

        self._subs = [_channel_subscriber(session, key, inbox, drain) for key in keys]

    @property
    def dropped(self) -> int:
        return self._inbox.dropped

    async def recv(self, timeout: float | None = None) -> RawSample:
        items = self._inbox.items
        key, payload, encoding, received_ns = (
            items.popleft() if items else await self._inbox.get(timeout)
        )
        if not isinstance(payload, bytes):
            payload = payload.to_bytes()
        return RawSample(key, payload, encoding, received_ns)

    def __aiter__(self) -> AsyncIterator[RawSample]:
        return _until_closed(self.recv)

    def close(self) -> None:
        if not self._inbox.closed:
            for sub in self._subs:
                undeclare(sub)
            self._inbox.close()


class Subscription(Generic[M]):
    """Decoded messages of one type on a key expression, delivered as `delivery` says: strict
    decoding (a payload that does not decode is counted in `malformed`, reported to
    `on_malformed(key, error)` and skipped), counting, async iteration. With `delivery.recover`,
    messages lost to a cut link or a late start come back from the publishers' caches, in order
    per publisher, once each; `recovered` counts those, `missed` those no cache held any more.
    With `shared` (a fleet process's stream of every robot, runtime.bus.demux), robot `robot`'s
    samples come from it and nothing is declared here."""

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        cls: type[M],
        loop: asyncio.AbstractEventLoop,
        delivery: Delivery = RELIABLE,
        on_malformed: MalformedHandler | None = None,
        *,
        shared: SharedSource | None = None,
        robot: str = "",
    ) -> None:
        self.key = key
        self.cls = cls
        self.delivery = delivery
        self.malformed = 0
        self.received = 0
        self._on_malformed = on_malformed
        self._recovering: RecoveringSource | None = None
        self._sub: zenoh.Subscriber[zenoh.handlers.Handler[zenoh.Sample]] | None = None
        self._shared = shared
        self._robot = robot
        if shared is not None:
            self._inbox: Inbox[WirePayload] = Inbox(loop, delivery.queue)
            shared.attach(robot, self._inbox)
        elif delivery.recover:
            self._inbox = Inbox(loop, delivery.queue)
            self._recovering = RecoveringSource(session, key, self._inbox, delivery)
        else:
            self._inbox = Inbox(loop, delivery.queue, wakeup_fd=True)
            self._sub = typed_channel_subscriber(session, key, self._inbox)

    @property
    def dropped(self) -> int:
        return self._inbox.dropped

    @property
    def recovered(self) -> int:
        """Messages that came from a publisher cache, not off the wire (0 without recovery)."""
        if self._shared is not None:
            return self._shared.recovered_of(self._robot)
        return 0 if self._recovering is None else self._recovering.recovered

    @property
    def missed(self) -> int:
        """Messages no publisher cache could give back any more (0 without recovery)."""
        if self._shared is not None:
            return self._shared.missed_of(self._robot)
        return 0 if self._recovering is None else self._recovering.missed

    @property
    def pending(self) -> int:
        """Messages received and not yet taken by the consumer."""
        return len(self._inbox)

    def _accept(
        self, key: str, payload: bytes | zenoh.ZBytes, received_ns: int
    ) -> Received[M] | None:
        """The decoded message, or None (counted) when the payload is malformed."""
        if not isinstance(payload, bytes):
            payload = payload.to_bytes()
        try:
            message = decode(payload, self.cls, key)
        except SchemaError as exc:
            self.malformed += 1
            if self._on_malformed is not None:
                self._on_malformed(key, exc)
            return None
        self.received += 1
        return Received(key, message, received_ns)

    def ready(self) -> Received[M] | None:
        """The next well-formed message already received, without waiting (None: none is):
        a consumer takes a burst with one wake-up and no coroutine per message."""
        items = self._inbox.items
        while items:
            got = self._accept(*items.popleft())
            if got is not None:
                return got
        return None

    async def recv(self, timeout: float | None = None) -> Received[M]:
        """The next well-formed message (malformed ones are counted and skipped)."""
        items = self._inbox.items
        while True:
            # Straight from the deque when something is waiting: no extra coroutine per message.
            item = items.popleft() if items else await self._inbox.get(timeout)
            got = self._accept(*item)
            if got is not None:
                return got

    def __aiter__(self) -> AsyncIterator[Received[M]]:
        return _until_closed(self.recv)

    def close(self) -> None:
        if not self._inbox.closed:
            if self._recovering is not None:
                self._recovering.close()
            if self._sub is not None:
                undeclare(self._sub)
            if self._shared is not None:
                self._shared.detach(self._robot, self._inbox)
            self._inbox.close()


Handler = Callable[[M], Awaitable[None] | None]


async def consume(
    sub: Subscription[M],
    handler: Handler[M],
    on_error: Callable[[str, Exception], None],
    *,
    before: Callable[[Received[M]], None] | None = None,
    after: Callable[[Received[M]], None] | None = None,
    accept: Callable[[Received[M]], bool] | None = None,
) -> None:
    """Call `handler(message)` (awaited if it returns an awaitable) for every message of `sub`
    until it closes: the one handler loop of services, players and views. What the handler
    raises goes to `on_error(key, exc)` and the loop goes on: one bad message must not stop a
    stream. `before`/`after` see every message, also one whose handler failed; a message
    `accept` refuses (handled already) is seen by `before` only. What is ready is taken without
    a coroutine or an async iterator step per message; the loop waits only when none is."""
    ready, recv = sub.ready, sub.recv
    while True:
        received = ready()
        if received is None:
            try:
                received = await recv()
            except EOFError:  # closed and drained
                return
        if before is not None:
            before(received)
        if accept is not None and not accept(received):
            continue
        try:
            result = handler(received.message)
            if result is not None and inspect.isawaitable(result):
                await result
        except asyncio.CancelledError:
            raise
        except Exception as exc:
            on_error(received.key, exc)
        if after is not None:
            after(received)


def decode_any(sample: RawSample) -> Message | None:
    """Decode a raw sample by its wire encoding or, failing that, by its key; None if neither
    names one of our types. Raises SchemaError when it should be ours but is not valid."""
    cls = type_from_encoding(sample.encoding) or type_for_key(sample.key)
    if cls is None:
        return None
    return decode(sample.payload, cls, sample.key)
