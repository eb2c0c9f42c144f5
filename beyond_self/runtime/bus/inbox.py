"""The hand-off from Zenoh's threads to one asyncio consumer, and the small Zenoh glue every
part of the bus shares.

Zenoh delivers samples on its own threads; asyncio code must not be touched from there. An
`Inbox` is a bounded deque (when full the oldest item is dropped and counted) plus at most one
wake-up of the event loop per burst, through an eventfd the loop watches (cheaper than
`loop.call_soon_threadsafe`, which needs a handle and a self-pipe drain).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import threading
from collections import deque
from collections.abc import Callable, Iterable
from typing import Generic, Protocol, TypeVar

import zenoh

from beyond_self.core.errors import InputError

T = TypeVar("T")
_EVENTFD_ONE = (1).to_bytes(8, "little")


class Undeclarable(Protocol):
    def undeclare(self) -> None: ...


def undeclare(entity: Undeclarable) -> None:
    """Undeclare a Zenoh entity; one already gone (its session closed) is not an error."""
    with contextlib.suppress(Exception):
        entity.undeclare()


def direct_callback(fn: Callable[[T], None]) -> zenoh.handlers.Callback[T]:
    """Run `fn` on the Zenoh network thread (it only appends to a deque), not on an extra
    Python thread. For the low-rate streams (queries, liveliness, matching, recovery);
    plain subscriptions use channels and a drain thread (runtime.bus.subscription)."""
    return zenoh.handlers.Callback(fn, indirect=False)


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
        self.items: deque[T] = deque()
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

    def _on_wakeup_fd(self) -> None:  # loop thread, on every wake-up: no context manager
        try:  # noqa: SIM105 - suppress() is a context manager per wake-up
            os.read(self._fd_read, 8 if self._fd_read == self._fd_write else 4096)
        except OSError:  # BlockingIOError: already read
            pass
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
                    try:  # noqa: SIM105 - as in _on_wakeup_fd
                        os.write(self._fd_write, _EVENTFD_ONE)
                    except OSError:  # full counter/pipe: a wake is pending
                        pass
                    return
        # RuntimeError: the loop is closed, nobody is listening any more.
        with contextlib.suppress(RuntimeError):
            self._loop.call_soon_threadsafe(self._wake)

    def push(self, item: T) -> None:  # any thread
        items = self.items
        if len(items) >= self._maxsize:
            items.popleft()
            self.dropped += 1
        items.append(item)
        if self._waiter is not None and not self._wake_pending:
            self._signal()

    def _append(self, batch: Iterable[T]) -> None:  # the oldest dropped beyond the bound
        items, maxsize = self.items, self._maxsize
        for item in batch:
            if len(items) >= maxsize:
                items.popleft()
                self.dropped += 1
            items.append(item)

    def extend(self, batch: Iterable[T]) -> None:  # any thread
        """Push several items with at most one wake-up."""
        self._append(batch)
        if self._waiter is not None and not self._wake_pending:
            self._signal()

    def extend_local(self, batch: Iterable[T]) -> None:  # loop thread
        """`extend` from the event loop's own thread (runtime.bus.demux hands a process-wide
        stream's burst to each run): the parked consumer is woken directly, with no eventfd."""
        self._append(batch)
        if self._waiter is not None:
            self._wake()

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
        return len(self.items)

    async def get(self, timeout: float | None = None) -> T:
        """The next item; TimeoutError after `timeout` s; EOFError once closed and drained."""
        items = self.items
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
