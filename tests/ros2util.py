"""rosbags' type store for the ROS 2 tests: what a third party builds its messages with."""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import Callable, Iterator

import numpy as np
import zenoh
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_typestore

from beyond_self.runtime.bus.session import Bus
from beyond_self.schemas.messages import Progress

STORE = get_typestore(Stores.ROS2_JAZZY)


def zero(node: tuple[int, object]) -> object:
    """A field of rosbags' type store at its zero value (rosbags needs every field)."""
    kind, detail = node
    if kind == Nodetype.NAME:
        assert isinstance(detail, str)
        return STORE.types[detail](**{n: zero(sub) for n, sub in STORE.fielddefs[detail][1]})
    if kind == Nodetype.BASE:
        assert isinstance(detail, tuple)
        return "" if detail[0] == "string" else False if detail[0] == "bool" else 0
    assert isinstance(detail, tuple)
    return np.zeros(0, np.uint8) if detail[0][0] == Nodetype.BASE else []


@contextlib.contextmanager
def plain_router(port: int) -> Iterator[zenoh.Session]:
    """A Zenoh router on loopback, nothing of ours in it (rmw_zenohd's part)."""
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps("router"))
    config.insert_json5("listen/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    config.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(config)
    try:
        yield session
    finally:
        session.close()  # type: ignore[no-untyped-call]


class ProgressWatch:
    """The services' `Progress` on a bus: what each has handled (service -> sensor key -> last
    stamp), and a wait until a condition on it holds, woken by each report and bounded, so a
    test paces what it sends by the pipeline's progress, never by a sleep."""

    def __init__(self, bus: Bus) -> None:
        self.bus = bus
        self.handled: dict[str, dict[str, int]] = {}
        self.moved = asyncio.Event()

    async def run(self) -> None:
        async for received in self.bus.subscribe(self.bus.keys.progress(), Progress):
            self.handled[received.message.service] = dict(received.message.handled)
            self.moved.set()

    async def until(self, done: Callable[[], bool], what: str, timeout_s: float = 20.0) -> None:
        try:
            async with asyncio.timeout(timeout_s):
                while not done():
                    self.moved.clear()
                    await self.moved.wait()
        except TimeoutError:
            raise AssertionError(f"no progress in {timeout_s} s: {what}; {self.handled}") from None
