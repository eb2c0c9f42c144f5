"""One Zenoh subscriber per stream for a whole fleet process, each sample handed to its robot's run.

Declared per run, every robot's sample cost a subscriber, a Zenoh thread taking the GIL and a
wake-up of the loop. Here a stream (a key below the robot, one `Delivery`) is declared once for
every robot of the fleet's pattern; its bursts reach one hub on the loop, which hands each robot's
samples to that run's inbox (`Inbox.extend_local`). Decoding, ledgers and event time stay the
run's. Samples that come before a robot's run subscribes (a restarted process gets every robot's
history at once) wait for it, up to the stream's queue; another shard's robots are not kept.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import zenoh

from beyond_self.runtime.bus.delivery import Delivery
from beyond_self.runtime.bus.inbox import Inbox, undeclare
from beyond_self.runtime.bus.recovery import RecoveringSource
from beyond_self.runtime.bus.subscription import WirePayload, typed_channel_subscriber
from beyond_self.schemas.keys import PREFIX, robot_matches, robot_of, split_key

# The hub is emptied by the loop at every wake-up, so it holds one burst at most; a run's inbox is
# the bound that drops (each its delivery's queue).
_HUB_CAPACITY = 1 << 20


@dataclass
class _Waiting:
    """A robot's samples that came before its run subscribed."""

    items: deque[WirePayload]
    dropped: int = 0


@dataclass
class SharedStream:
    """One stream (a key expression below the robot, one `Delivery`) for every robot."""

    expr: str  # beyond/<pattern>/<suffix>
    delivery: Delivery
    serves: Callable[[str], bool]  # whether a robot's samples are kept for its run
    runs: dict[str, list[Inbox[WirePayload]]] = field(default_factory=dict)
    waiting: dict[str, _Waiting] = field(default_factory=dict)
    recovering: RecoveringSource | None = None

    def hand_over(self, batch: list[WirePayload]) -> None:  # loop thread
        """Give each robot's samples of `batch`, in order, to its run (or keep them)."""
        per_robot: dict[str, list[WirePayload]] = {}
        for item in batch:
            robot = robot_of(item[0])
            got = per_robot.get(robot)
            if got is None:
                per_robot[robot] = [item]
            else:
                got.append(item)
        for robot, items in per_robot.items():
            inboxes = self.runs.get(robot)
            if inboxes:
                for inbox in inboxes:
                    inbox.extend_local(items)
            elif self.serves(robot):
                waiting = self.waiting.get(robot)
                if waiting is None:
                    waiting = self.waiting[robot] = _Waiting(deque())
                for item in items:
                    if len(waiting.items) >= self.delivery.queue:
                        waiting.items.popleft()
                        waiting.dropped += 1
                    waiting.items.append(item)

    def attach(self, robot: str, inbox: Inbox[WirePayload]) -> None:
        """Robot `robot`'s run subscribes: what waited for it first, then what comes."""
        waiting = self.waiting.pop(robot, None)
        if waiting is not None:
            inbox.dropped += waiting.dropped
            inbox.extend_local(waiting.items)
        self.runs.setdefault(robot, []).append(inbox)

    def detach(self, robot: str, inbox: Inbox[WirePayload]) -> None:
        inboxes = self.runs.get(robot, [])
        with contextlib.suppress(ValueError):
            inboxes.remove(inbox)
        if not inboxes:
            self.runs.pop(robot, None)

    def forget(self, robot: str) -> None:
        """Drop what waits for `robot` (the fleet no longer expects to serve it)."""
        self.waiting.pop(robot, None)

    def recovered_of(self, robot: str) -> int:
        return 0 if self.recovering is None else self.recovering.recovered_of(robot)

    def missed_of(self, robot: str) -> int:
        return 0 if self.recovering is None else self.recovering.missed_of(robot)


class SharedStreams:
    """A fleet process's shared streams (runtime.fleet): declared on a run's first subscribe
    to each, closed with the fleet. `pattern` is the robots' key chunk (schemas.keys)."""

    def __init__(self, session: zenoh.Session, pattern: str, serves: Callable[[str], bool]) -> None:
        self._session = session
        self._pattern = pattern
        self._serves = serves
        self._streams: dict[tuple[str, Delivery], SharedStream] = {}
        self._closers: list[Callable[[], None]] = []
        self._tasks: set[asyncio.Task[None]] = set()

    def stream_of(self, key: str, robot: str, delivery: Delivery) -> SharedStream | None:
        """The shared stream that feeds robot `robot`'s subscription to `key`; None when `key`
        is not one of that robot's own or the robot is not one of the pattern's."""
        split = split_key(key)
        if split is None or split[0] != robot or not robot_matches(self._pattern, robot):
            return None
        return self.stream(split[1], delivery)

    def stream(self, suffix: str, delivery: Delivery) -> SharedStream:
        """The shared stream of `beyond/<robot>/<suffix>` for every robot, declared if new."""
        found = self._streams.get((suffix, delivery))
        if found is not None:
            return found
        expr = f"{PREFIX}/{self._pattern}/{suffix}"
        stream = SharedStream(expr, delivery, self._serves)
        hub: Inbox[WirePayload] = Inbox(asyncio.get_running_loop(), _HUB_CAPACITY, wakeup_fd=True)
        if delivery.recover:
            stream.recovering = RecoveringSource(self._session, expr, hub, delivery, shared=True)
            self._closers.append(stream.recovering.close)
        else:
            sub = typed_channel_subscriber(self._session, expr, hub)
            self._closers.append(lambda: undeclare(sub))
        self._closers.append(hub.close)
        task = asyncio.get_running_loop().create_task(_hand_over(hub, stream), name=expr)
        self._tasks.add(task)
        self._streams[(suffix, delivery)] = stream
        return stream

    def forget(self, robot: str) -> None:
        """Drop every stream's samples waiting for `robot`."""
        for stream in self._streams.values():
            stream.forget(robot)

    def close(self) -> None:
        for closer in self._closers:
            with contextlib.suppress(Exception):
                closer()
        self._closers.clear()
        for task in self._tasks:
            task.cancel()
        self._streams.clear()


async def _hand_over(hub: Inbox[WirePayload], stream: SharedStream) -> None:
    """The hub's consumer: every burst that came, handed to the runs with one wake-up."""
    items = hub.items
    while True:
        try:
            first = await hub.get()
        except EOFError:
            return
        batch = [first]
        while items:
            batch.append(items.popleft())
        stream.hand_over(batch)
