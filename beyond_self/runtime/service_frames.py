"""Per-frame work that never goes before per-gesture work: a service's `FrameSchedule`.

A frame's own result (the objects of a camera frame) is the costly part, and no gesture result
waits for it. So a frame first lets a gesture event already received go before it
(`YIELDS_TO_EVENTS` turns of the event loop); a live source's frames (`newest`) are worked on
newest first beside the handlers, an overtaken one skipped and counted, while a replay's every
frame is worked on before it counts as handled (the player is paced on it); and the worker process
runs at a lower priority when live (`niceness`). `Steps` runs work that comes in small steps one
per turn of the event loop, so that a message waiting goes between two steps.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable, Sequence
from typing import Any, Generic, Protocol, TypeVar

from beyond_self.runtime.bus.subscription import Subscription

F = TypeVar("F")

YIELDS_TO_EVENTS = 8  # turns of the event loop a frame gives waiting gesture events
LIVE_NICENESS = 10  # of a live source's worker process: what the gestures leave, it gets


class Spawner(Protocol):
    def spawn(self, work: Any, name: str = ...) -> Any: ...


class FrameSchedule(Generic[F]):
    """`await put(frame)` after the per-gesture part of a frame: `work(frame)` now (a replay),
    or for the newest frame whenever the last work is done (`newest`, a live source)."""

    def __init__(
        self,
        service: Spawner,
        work: Callable[[F], Awaitable[None]],
        events: Sequence[Subscription[Any]],
        *,
        newest: bool,
    ) -> None:
        self.work = work
        self.events = events
        self.newest = newest
        self.niceness = LIVE_NICENESS if newest else 0
        self.skipped = 0  # frames not worked on: a newer one overtook them
        self._overtaken = 0  # since the last `overtaken()`
        self._waiting: F | None = None
        self._ready = asyncio.Event()
        if newest:
            service.spawn(self._newest(), "work on the newest frame")

    async def events_first(self) -> None:
        """Let a gesture event already received go first (at most YIELDS_TO_EVENTS turns)."""
        for _ in range(YIELDS_TO_EVENTS):
            if not any(sub.pending for sub in self.events):
                break
            await asyncio.sleep(0)

    async def put(self, frame: F) -> None:
        if not self.newest:
            await self.work(frame)  # before the frame counts as handled: paced
            return
        if self._waiting is not None:
            self.skipped += 1
            self._overtaken += 1
        self._waiting = frame
        self._ready.set()

    def overtaken(self) -> int:
        """Frames skipped since the last call (an output says how many it overtook)."""
        skipped, self._overtaken = self._overtaken, 0
        return skipped

    async def _newest(self) -> None:
        while True:
            await self._ready.wait()
            self._ready.clear()
            if self._waiting is not None:
                frame, self._waiting = self._waiting, None
                await self.work(frame)


class Steps:
    """`step()` (True: more to do) called until done after each `poke()`, one call per turn
    of the event loop, beside the service's handlers."""

    def __init__(self, service: Spawner, step: Callable[[], bool], name: str = "steps") -> None:
        self.step = step
        self._behind = asyncio.Event()
        service.spawn(self._run(), name)

    def poke(self) -> None:
        self._behind.set()

    async def _run(self) -> None:
        while True:
            await self._behind.wait()
            self._behind.clear()
            while self.step():
                await asyncio.sleep(0)
