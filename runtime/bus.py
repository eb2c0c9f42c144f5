"""Typed publish/subscribe, query/reply and liveliness over one Zenoh session.

Zenoh delivers samples on its own threads; asyncio code must not be touched from there.

Subscriptions receive through a Zenoh FIFO channel, not a Python callback: Zenoh's network thread
then never takes the GIL (a callback run there, `indirect=False`, has to create a Python thread
state per sample; measured 3x fewer samples per second than an indirect callback). One small
drain thread per subscription blocks in the channel's `recv()` with the GIL released, takes
whatever else has arrived with `try_recv()`, copies each payload, and hands the whole burst to
the subscription's inbox in one go: a bounded deque (when full the oldest item is dropped and
counted) plus at most one wake-up of the event loop per burst, through an eventfd the loop
watches (cheaper than `loop.call_soon_threadsafe`, which needs a handle and a self-pipe drain).
Decoding happens on the event loop when the consumer takes the sample, so the drain thread never
runs user code, and a malformed payload is counted and reported on the loop; payloads larger than
a Zenoh batch (camera frames) are also copied out of Zenoh there, just before decoding reads them.
Publishers encode into one reused buffer. bench/bus.py measures all of this against raw
zenoh-python and explains what limits the ratios.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import threading
import time
from collections import deque
from collections.abc import AsyncIterator, Awaitable, Callable, Iterable
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import zenoh

from core.errors import InputError
from runtime.config import BusConfig, describe, load_config, zenoh_config
from schemas.base import Message
from schemas.codec import (
    SchemaError,
    decode,
    encode,
    encode_into,
    type_from_encoding,
    wire_encoding,
)
from schemas.keys import Keys, type_for_key

M = TypeVar("M", bound=Message)
T = TypeVar("T")
log = logging.getLogger("beyond.bus")

MalformedHandler = Callable[[str, SchemaError], None]

# Zenoh-side staging channel of a subscription. The inbox behind it is the real bound (drops
# oldest, counted); this one only has to absorb a burst while the drain thread waits for the GIL
# (when it is full, Zenoh's network thread waits, as it did for the GIL with a callback).
_CHANNEL_CAPACITY = 256
_BURST = 256  # samples handed to the inbox per wake-up at most
_EVENTFD_ONE = (1).to_bytes(8, "little")


@dataclass(slots=True, frozen=True)
class RawSample:
    """A sample as it came off the wire."""

    key: str
    payload: bytes
    encoding: str
    received_ns: int  # wall clock (ns since epoch) when the sample was taken off Zenoh


@dataclass(slots=True, frozen=True)
class Received(Generic[M]):
    """A decoded message and where/when it arrived."""

    key: str
    message: M
    received_ns: int


def _callback(fn: Callable[[Any], None]) -> Any:
    """Run `fn` on the Zenoh network thread (it only appends to a deque), not on an extra
    Python thread. For the low-rate helpers (queries, liveliness, matching); subscriptions use
    channels and a drain thread."""
    try:
        return zenoh.handlers.Callback(fn, indirect=False)
    except TypeError:  # older zenoh-python without `indirect`
        return fn


class Inbox(Generic[T]):
    """Thread-safe hand-off from Zenoh threads to one asyncio consumer.

    `push`/`extend` may be called from any thread; `get` and `close` on the loop. With
    `wakeup_fd`, wake-ups go through an eventfd (a pipe where there is none) watched by the loop;
    otherwise (and on loops without `add_reader`) through `call_soon_threadsafe`."""

    def __init__(
        self, loop: asyncio.AbstractEventLoop, maxsize: int, *, wakeup_fd: bool = False
    ) -> None:
        if maxsize < 1:
            raise InputError(f"queue size {maxsize} must be at least 1")
        self._loop = loop
        self._items: deque[T] = deque()
        self._maxsize = maxsize
        self._waiter: asyncio.Future[None] | None = None
        self._wake_pending = False
        self.closed = False
        self.dropped = 0
        self._fd_lock = threading.Lock()
        self._fd_read = self._fd_write = -1
        if wakeup_fd:
            self._open_wakeup_fd()

    def _open_wakeup_fd(self) -> None:
        try:
            if hasattr(os, "eventfd"):
                read = write = os.eventfd(0, os.EFD_NONBLOCK | os.EFD_CLOEXEC)
            else:  # pragma: no cover - non-Linux
                read, write = os.pipe()
                os.set_blocking(read, False)
                os.set_blocking(write, False)
        except OSError:  # out of descriptors: fall back to call_soon_threadsafe
            return
        try:
            self._loop.add_reader(read, self._on_wakeup_fd)
        except (NotImplementedError, RuntimeError):  # e.g. a proactor loop
            for fd in {read, write}:
                os.close(fd)
            return
        self._fd_read, self._fd_write = read, write

    def _on_wakeup_fd(self) -> None:  # loop thread
        with contextlib.suppress(OSError):  # BlockingIOError: already read
            os.read(self._fd_read, 8 if self._fd_read == self._fd_write else 4096)
        self._wake()

    def _close_wakeup_fd(self) -> None:  # loop thread
        with self._fd_lock:  # no producer is between its check and its write
            read, write = self._fd_read, self._fd_write
            self._fd_read = self._fd_write = -1
        if read < 0:
            return
        with contextlib.suppress(Exception):
            self._loop.remove_reader(read)
        for fd in {read, write}:
            with contextlib.suppress(OSError):
                os.close(fd)

    def _signal(self) -> None:  # any thread; the consumer is parked
        self._wake_pending = True
        if self._fd_write >= 0:
            with self._fd_lock:
                if self._fd_write >= 0:
                    with contextlib.suppress(OSError):  # full counter/pipe: a wake is pending
                        os.write(self._fd_write, _EVENTFD_ONE)
                    return
        # RuntimeError: the loop is closed, nobody is listening any more.
        with contextlib.suppress(RuntimeError):
            self._loop.call_soon_threadsafe(self._wake)

    def push(self, item: T) -> None:  # any thread
        items = self._items
        if len(items) >= self._maxsize:
            items.popleft()
            self.dropped += 1
        items.append(item)
        if self._waiter is not None and not self._wake_pending:
            self._signal()

    def extend(self, batch: Iterable[T]) -> None:  # any thread
        """Push several items with at most one wake-up."""
        items, maxsize = self._items, self._maxsize
        for item in batch:
            if len(items) >= maxsize:
                items.popleft()
                self.dropped += 1
            items.append(item)
        if self._waiter is not None and not self._wake_pending:
            self._signal()

    def _wake(self) -> None:  # loop thread
        self._wake_pending = False
        waiter, self._waiter = self._waiter, None
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def close(self) -> None:  # loop thread
        self.closed = True
        self._close_wakeup_fd()
        self._wake()

    def __len__(self) -> int:
        return len(self._items)

    async def get(self, timeout: float | None = None) -> T:
        """The next item; TimeoutError after `timeout` s; EOFError once closed and drained."""
        items = self._items
        loop = self._loop
        deadline = None if timeout is None else loop.time() + timeout
        while not items:
            if self.closed:
                raise EOFError("inbox closed")
            remaining = 0.0
            if deadline is not None:
                remaining = deadline - loop.time()
                if remaining <= 0:
                    raise TimeoutError("no message before the timeout")
            waiter = self._waiter = loop.create_future()
            if items or self.closed:  # arrived between the check and parking
                self._waiter = None
                continue
            # A timer on our own future rather than asyncio.wait_for, which wraps it in a second
            # future: one more trip round the event loop for every wake-up.
            timer = None if deadline is None else loop.call_later(remaining, _expire, waiter)
            try:
                await waiter
            finally:
                if timer is not None:
                    timer.cancel()
                if self._waiter is waiter:
                    self._waiter = None
        return items.popleft()


def _expire(waiter: asyncio.Future[None]) -> None:
    if not waiter.done():
        waiter.set_result(None)


def _drain(handler: Any, inbox: Inbox[T], convert: Callable[[Any, int], T]) -> None:
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
            sample = try_recv()
            if sample is None:
                break
            batch.append(convert(sample, now()))
        inbox.extend(batch)


def _channel_subscriber(
    session: Any, key: str, inbox: Inbox[T], convert: Callable[[Any, int], T]
) -> Any:
    """Declare a subscriber on `key` whose samples reach `inbox` through a drain thread."""
    sub = session.declare_subscriber(key, zenoh.handlers.FifoChannel(_CHANNEL_CAPACITY))
    thread = threading.Thread(
        target=_drain, args=(sub.handler, inbox, convert), name=f"zenoh-drain {key}", daemon=True
    )
    thread.start()
    return sub


# Payloads above Zenoh's batch size were reassembled into a buffer of their own, so keeping the
# sample pins nothing else; they are copied out on the loop, right before decoding reads them.
_COPY_ON_LOOP = 64 * 1024


def _raw_sample(sample: Any, received_ns: int) -> RawSample:
    """A RawSample whose payload, when large, is still Zenoh's ZBytes (see `_COPY_ON_LOOP`);
    `RawSubscription.recv` copies it out."""
    payload = sample.payload
    if len(payload) <= _COPY_ON_LOOP:
        payload = payload.to_bytes()
    return RawSample(str(sample.key_expr), payload, str(sample.encoding), received_ns)


def _sample_converter(key: str) -> Callable[[Any, int], tuple[str, Any, int]]:
    """Drain-thread conversion for a typed subscription: (key, payload, received_ns), the
    payload as bytes, or for a large one still as Zenoh's ZBytes."""
    if "*" in key or "$" in key:  # a wildcard: each sample says which key it came on

        def convert(sample: Any, received_ns: int) -> tuple[str, Any, int]:
            payload = sample.payload
            if len(payload) <= _COPY_ON_LOOP:
                payload = payload.to_bytes()
            return (str(sample.key_expr), payload, received_ns)

    else:  # one key: no need to build its string for every sample

        def convert(sample: Any, received_ns: int) -> tuple[str, Any, int]:
            payload = sample.payload
            if len(payload) <= _COPY_ON_LOOP:
                payload = payload.to_bytes()
            return (key, payload, received_ns)

    return convert


class RawSubscription:
    """Undecoded samples of one or more key expressions (recorder, echo): in arrival order per
    key expression (each has its own Zenoh subscriber)."""

    def __init__(
        self, session: Any, keys: list[str], loop: asyncio.AbstractEventLoop, maxsize: int
    ) -> None:
        self.keys = keys
        self._inbox: Inbox[RawSample] = Inbox(loop, maxsize, wakeup_fd=True)
        self._subs = [_channel_subscriber(session, key, self._inbox, _raw_sample) for key in keys]

    @property
    def dropped(self) -> int:
        return self._inbox.dropped

    async def recv(self, timeout: float | None = None) -> RawSample:
        items = self._inbox._items
        sample = items.popleft() if items else await self._inbox.get(timeout)
        if type(sample.payload) is not bytes:
            payload: Any = sample.payload
            sample = RawSample(sample.key, payload.to_bytes(), sample.encoding, sample.received_ns)
        return sample

    def __aiter__(self) -> AsyncIterator[RawSample]:
        return self._iterate()

    async def _iterate(self) -> AsyncIterator[RawSample]:
        while True:
            try:
                yield await self.recv()
            except EOFError:
                return

    def close(self) -> None:
        if not self._inbox.closed:
            for sub in self._subs:
                _undeclare(sub)
            self._inbox.close()


class DecodedStream(Generic[M]):
    """What every typed subscription shares: strict decoding, counting and async iteration over
    an inbox of (key, payload, received_ns). A payload that does not decode is counted in
    `malformed`, reported to `on_malformed(key, error)` and skipped. Subclasses fill `_inbox`."""

    key: str
    cls: type[M]
    malformed: int
    received: int
    _on_malformed: MalformedHandler | None
    _inbox: Inbox[Any]

    @property
    def dropped(self) -> int:
        return self._inbox.dropped

    def _accept(self, key: str, payload: Any, received_ns: int) -> Received[M] | None:
        """The decoded message, or None (counted) when the payload is malformed."""
        if type(payload) is not bytes:
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

    async def recv(self, timeout: float | None = None) -> Received[M]:
        """The next well-formed message (malformed ones are counted and skipped)."""
        while True:
            got = self._accept(*await self._inbox.get(timeout))
            if got is not None:
                return got

    def __aiter__(self) -> AsyncIterator[Received[M]]:
        return self._iterate()

    async def _iterate(self) -> AsyncIterator[Received[M]]:
        while True:
            try:
                yield await self.recv()
            except EOFError:
                return


class Subscription(DecodedStream[M]):
    """Decoded messages of one type on a key expression (see `DecodedStream`)."""

    def __init__(
        self,
        session: Any,
        key: str,
        cls: type[M],
        loop: asyncio.AbstractEventLoop,
        maxsize: int,
        on_malformed: MalformedHandler | None,
    ) -> None:
        self.key = key
        self.cls = cls
        self.malformed = 0
        self.received = 0
        self._on_malformed = on_malformed
        self._inbox: Inbox[tuple[str, Any, int]] = Inbox(loop, maxsize, wakeup_fd=True)
        self._sub = _channel_subscriber(session, key, self._inbox, _sample_converter(key))

    async def recv(self, timeout: float | None = None) -> Received[M]:
        """The next well-formed message (malformed ones are counted and skipped)."""
        items = self._inbox._items
        while True:
            # Straight from the deque when something is waiting: no extra coroutine per message.
            item = items.popleft() if items else await self._inbox.get(timeout)
            got = self._accept(*item)
            if got is not None:
                return got

    def close(self) -> None:
        if not self._inbox.closed:
            _undeclare(self._sub)
            self._inbox.close()


class Publisher(Generic[M]):
    """Publishes messages of one type on one key. `reliable` (the default) blocks briefly when
    Zenoh's queue is full instead of dropping: derived results and replays must not vanish."""

    def __init__(
        self, session: Any, key: str, cls: type[M], *, reliable: bool = True, express: bool = False
    ) -> None:
        self.key = key
        self.cls = cls
        self.sent = 0
        self.last_stamp = -1  # of the last message sent
        self.skip_until = -1  # messages stamped at or before this are not sent (a restart)
        self.suppressed = 0
        self._owner = threading.get_ident()
        self._buffer = bytearray()
        self._pub = session.declare_publisher(
            key,
            encoding=zenoh.Encoding(wire_encoding(cls)),
            congestion_control=(
                zenoh.CongestionControl.BLOCK if reliable else zenoh.CongestionControl.DROP
            ),
            express=express,
        )

    def put(self, message: M) -> None:
        if type(message) is not self.cls:
            raise TypeError(f"publisher of {self.cls.__name__} got {type(message).__name__}")
        stamp = message.header.stamp
        if stamp <= self.skip_until:
            self.suppressed += 1  # a previous instance of this service already published it
            return
        self.last_stamp = stamp
        if threading.get_ident() == self._owner:
            # One buffer reused for every put (Zenoh copies it before `put` returns): no fresh
            # block per message, which for camera frames costs more than encoding them.
            buffer = self._buffer
            encode_into(message, buffer)
            self._pub.put(buffer)
        else:  # another thread: it must not share the buffer
            self._pub.put(encode(message))
        self.sent += 1

    def put_bytes(self, payload: bytes) -> None:
        """Publish an already encoded payload (replay, benchmarks)."""
        self._pub.put(payload)
        self.sent += 1

    def matching(self) -> bool:
        """Whether any subscriber currently matches this key."""
        return bool(self._pub.matching_status.matching)

    async def wait_matching(self, timeout: float = 5.0) -> None:
        """Wait until a subscriber matches (discovery handshake, not a fixed sleep)."""
        loop = asyncio.get_running_loop()
        inbox: Inbox[bool] = Inbox(loop, 16)
        listener = self._pub.declare_matching_listener(
            _callback(lambda status: inbox.push(bool(status.matching)))
        )
        try:
            deadline = loop.time() + timeout
            while not self.matching():
                remaining = deadline - loop.time()
                if remaining <= 0:
                    raise TimeoutError(f"no subscriber for {self.key} within {timeout} s")
                with contextlib.suppress(TimeoutError):
                    await inbox.get(min(remaining, 0.5))
        finally:
            with contextlib.suppress(Exception):
                listener.undeclare()

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self._pub.undeclare()


QueryHandler = Callable[[str, bytes | None], Awaitable[list[tuple[str, Message]] | Message | None]]


class Bus:
    """One Zenoh session plus the helpers every service and tool uses."""

    def __init__(self, session: Any, config: BusConfig) -> None:
        self.session = session
        self.config = config
        self.keys = Keys(config.robot)
        self._closers: list[Callable[[], None]] = []
        self._tasks: set[asyncio.Task[None]] = set()
        # set by a Service: refuses (raises) a queryable key its class did not declare
        self.guard: Callable[[str], object] | None = None

    @classmethod
    def open(cls, config: BusConfig | None = None) -> Bus:
        config = config or load_config()
        log.debug("opening Zenoh session: %s", describe(config))
        try:
            session = zenoh.open(zenoh_config(config))
        except zenoh.ZError as exc:
            raise InputError(f"cannot open the Zenoh session ({describe(config)}): {exc}") from None
        return cls(session, config)

    def __enter__(self) -> Bus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def zid(self) -> str:
        return str(self.session.zid())

    def publisher(
        self, key: str, cls: type[M], *, reliable: bool = True, express: bool = False
    ) -> Publisher[M]:
        pub = Publisher(self.session, key, cls, reliable=reliable, express=express)
        self._closers.append(pub.close)
        return pub

    def raw_publisher(self, key: str, encoding: str, *, reliable: bool = True) -> Any:
        """A plain Zenoh publisher with an encoding string (replay of arbitrary channels)."""
        pub = self.session.declare_publisher(
            key,
            encoding=zenoh.Encoding(encoding) if encoding else None,
            congestion_control=(
                zenoh.CongestionControl.BLOCK if reliable else zenoh.CongestionControl.DROP
            ),
        )
        self._closers.append(lambda: _undeclare(pub))
        return pub

    def subscribe(
        self,
        key: str,
        cls: type[M],
        *,
        maxsize: int = 1024,
        on_malformed: MalformedHandler | None = None,
    ) -> Subscription[M]:
        """Typed subscription; must be called from the event loop that will consume it."""
        sub = Subscription(
            self.session, key, cls, asyncio.get_running_loop(), maxsize, on_malformed
        )
        self._closers.append(sub.close)
        return sub

    def subscribe_raw(self, keys: str | list[str], *, maxsize: int = 4096) -> RawSubscription:
        """Raw samples of one or more key expressions (give non-overlapping ones: a sample
        matching two of them arrives twice)."""
        keys = [keys] if isinstance(keys, str) else list(keys)
        sub = RawSubscription(self.session, keys, asyncio.get_running_loop(), maxsize)
        self._closers.append(sub.close)
        return sub

    # --- query / reply -------------------------------------------------------------------

    def queryable(self, key: str, handler: QueryHandler) -> Callable[[], None]:
        """Answer queries on `key` with `handler(query_key, payload)`, run on the event loop.
        The handler returns a message (replied on the query's key), a list of (key, message),
        or None (no reply). Returns a function that undeclares the queryable."""
        loop = asyncio.get_running_loop()
        inbox: Inbox[Any] = Inbox(loop, 256)
        queryable = self.session.declare_queryable(key, _callback(inbox.push))

        async def serve() -> None:
            while True:
                try:
                    query = await inbox.get()
                except EOFError:
                    return
                try:
                    payload = query.payload.to_bytes() if query.payload is not None else None
                    answer = await handler(str(query.key_expr), payload)
                    replies = (
                        [(str(query.key_expr), answer)] if isinstance(answer, Message) else answer
                    ) or []
                    for reply_key, message in replies:
                        query.reply(
                            reply_key,
                            encode(message),
                            encoding=zenoh.Encoding(wire_encoding(type(message))),
                        )
                except Exception as exc:
                    log.warning("query on %s failed: %s", key, exc)
                    with contextlib.suppress(Exception):
                        query.reply_err(str(exc))
                finally:
                    query.drop()

        task = loop.create_task(serve())
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

        def close() -> None:
            _undeclare(queryable)
            inbox.close()

        self._closers.append(close)
        return close

    async def query(
        self,
        selector: str,
        cls: type[M],
        *,
        payload: Message | None = None,
        timeout: float = 2.0,
    ) -> list[Received[M]]:
        """Ask every matching queryable; their well-formed replies (malformed ones raise)."""
        loop = asyncio.get_running_loop()
        inbox: Inbox[Any] = Inbox(loop, 4096)
        done = loop.create_future()

        def resolve() -> None:
            if not done.done():
                done.set_result(None)

        def finished() -> None:
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(resolve)

        kwargs: dict[str, Any] = {"timeout": timeout}
        if payload is not None:
            kwargs["payload"] = encode(payload)
            kwargs["encoding"] = zenoh.Encoding(wire_encoding(type(payload)))
        handler = zenoh.handlers.Callback(inbox.push, finished)
        self.session.get(selector, handler, **kwargs)
        await asyncio.wait_for(done, timeout + 1.0)
        replies: list[Received[M]] = []
        while len(inbox):
            reply = await inbox.get(0)
            sample = reply.ok
            if sample is None:
                err = reply.err
                detail = err.payload.to_string() if err is not None else "?"
                raise InputError(f"query {selector} answered with an error: {detail}")
            key = str(sample.key_expr)
            message = decode(sample.payload.to_bytes(), cls, key)
            replies.append(Received(key, message, time.time_ns()))
        return replies

    # --- liveliness ----------------------------------------------------------------------

    def declare_token(self, key: str) -> Callable[[], None]:
        """Liveliness token (other processes see it until we undeclare or die)."""
        token = self.session.liveliness().declare_token(key)
        closer = lambda: _undeclare(token)  # noqa: E731
        self._closers.append(closer)
        return closer

    def watch_tokens(
        self, key_expr: str, on_change: Callable[[str, bool], None]
    ) -> Callable[[], None]:
        """Call `on_change(key, present)` on the event loop for every liveliness token matching
        `key_expr` that appears (including those already there) or goes. Returns the undeclare."""
        loop = asyncio.get_running_loop()

        def on_sample(sample: Any) -> None:  # Zenoh thread
            present = sample.kind == zenoh.SampleKind.PUT
            with contextlib.suppress(RuntimeError):  # loop closed: nobody is listening
                loop.call_soon_threadsafe(on_change, str(sample.key_expr), present)

        sub = self.session.liveliness().declare_subscriber(
            key_expr, _callback(on_sample), history=True
        )
        closer = lambda: _undeclare(sub)  # noqa: E731
        self._closers.append(closer)
        return closer

    async def wait_alive(self, key_expr: str, count: int = 1, timeout: float = 10.0) -> set[str]:
        """Wait until at least `count` distinct liveliness tokens match `key_expr`."""
        return await self._wait_tokens(key_expr, lambda n: n >= count, f"{count}", timeout)

    async def wait_gone(self, key_expr: str, timeout: float = 10.0) -> None:
        """Wait until no liveliness token matches `key_expr` (services have stopped)."""
        await self._wait_tokens(key_expr, lambda n: n == 0, "0", timeout)

    async def _wait_tokens(
        self, key_expr: str, done: Callable[[int], bool], wanted: str, timeout: float
    ) -> set[str]:
        loop = asyncio.get_running_loop()
        inbox: Inbox[tuple[str, bool]] = Inbox(loop, 1024)

        def on_sample(sample: Any) -> None:
            inbox.push((str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT))

        sub = self.session.liveliness().declare_subscriber(
            key_expr, _callback(on_sample), history=True
        )
        # The history arrives as samples too; a query answers "none" for the empty case.
        alive: set[str] = set(await self.alive(key_expr, timeout=min(timeout, 1.0)))
        deadline = loop.time() + timeout
        try:
            while True:
                while len(inbox):
                    key, present = await inbox.get(0)
                    (alive.add if present else alive.discard)(key)
                if done(len(alive)):
                    return alive
                remaining = deadline - loop.time()
                try:
                    key, present = await inbox.get(max(remaining, 0.0))
                except TimeoutError:
                    raise TimeoutError(
                        f"{len(alive)} live tokens on {key_expr} after {timeout} s, wanted "
                        f"{wanted}: {sorted(alive)}"
                    ) from None
                (alive.add if present else alive.discard)(key)
        finally:
            _undeclare(sub)

    async def alive(self, key_expr: str, timeout: float = 1.0) -> list[str]:
        """Keys of the liveliness tokens currently matching `key_expr`."""

        def get() -> list[str]:
            replies = self.session.liveliness().get(key_expr, timeout=timeout)
            return sorted({str(r.ok.key_expr) for r in replies if r.ok is not None})

        return await asyncio.to_thread(get)

    def close(self) -> None:
        for closer in reversed(self._closers):
            with contextlib.suppress(Exception):
                closer()
        self._closers.clear()
        for task in list(self._tasks):
            task.cancel()
        with contextlib.suppress(Exception):
            self.session.close()


def _undeclare(entity: Any) -> None:
    with contextlib.suppress(Exception):
        entity.undeclare()


def decode_any(sample: RawSample) -> Message | None:
    """Decode a raw sample by its wire encoding or, failing that, by its key; None if neither
    names one of our types. Raises SchemaError when it should be ours but is not valid."""
    cls = type_from_encoding(sample.encoding) or type_for_key(sample.key)
    if cls is None:
        return None
    return decode(sample.payload, cls, sample.key)
