"""runtime.process.heap: a service process settles its heap after set-up, once per burst, and
hands it
back when a run ends; a process that is not a service's own keeps the collector as it was."""

from __future__ import annotations

import asyncio
import gc
import weakref
from collections.abc import Iterator

import pytest

from beyond_self.runtime.process import heap


class _Node:
    def __init__(self) -> None:
        self.me = self  # a reference cycle: only the collector frees it


@pytest.fixture
def managed(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    monkeypatch.setattr(heap, "_managed", True)
    yield
    gc.unfreeze()


async def test_a_settle_collects_the_garbage_then_freezes_what_lives(managed: None) -> None:
    garbage, kept = _Node(), _Node()
    gone = weakref.ref(garbage)
    del garbage
    heap.settle_soon(0.01)
    await asyncio.sleep(0.1)
    assert gone() is None
    assert gc.get_freeze_count() > 0
    assert not any(obj is kept for obj in gc.get_objects())  # frozen: no pass walks it
    heap.release()
    assert gc.get_freeze_count() == 0
    assert any(obj is kept for obj in gc.get_objects())


async def test_a_burst_of_starts_settles_once(
    managed: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    settles: list[int] = []
    monkeypatch.setattr(heap, "settle_now", lambda: settles.append(1))
    for _ in range(20):
        heap.settle_soon(0.05)
    await asyncio.sleep(0.2)
    assert settles == [1]
    heap.settle_soon(0.01)  # a later start settles again
    await asyncio.sleep(0.1)
    assert settles == [1, 1]


async def test_a_process_that_is_not_a_services_own_is_left_alone() -> None:
    assert not heap._managed  # pytest's process: services run in it, it is not theirs
    heap.settle_soon(0.01)
    await asyncio.sleep(0.1)
    assert gc.get_freeze_count() == 0
