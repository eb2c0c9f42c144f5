"""The source's flight recorder (runtime.resilience.source_log, issue 39): what went in comes back
from a
position on, across a restart and a file cut short by a kill, within a bound on bytes."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from busutil_net import private_config

import beyond_self.schemas as s
from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.delivery import SKELETON
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.resilience.source_log import SEGMENTS, SourceLog
from beyond_self.services.ingest import SensorIngest


def test_messages_come_back_from_a_position_on_and_after_a_restart(tmp_path: Path) -> None:
    log = SourceLog(tmp_path, max_bytes=SEGMENTS * 64 * 1024)
    for i in range(100):
        log.append("r/skeleton", 1000 + i, f"frame {i}".encode(), "application/msgpack")
        log.append("r/camera", 1000 + i, b"x" * 10, "application/msgpack")
    log.flush()  # a kill now: no footer, the open chunk written
    again = SourceLog(tmp_path, max_bytes=SEGMENTS * 64 * 1024)
    again.append("r/skeleton", 2000, b"after", "application/msgpack")
    again.close()
    got = list(again.since({"r/skeleton": 1090}))
    assert [(k, s, p) for k, s, p, _ in got] == [
        *(("r/skeleton", 1000 + i, f"frame {i}".encode()) for i in range(90, 100)),
        ("r/skeleton", 2000, b"after"),
    ]
    assert len(again.segments()) == 2


def test_the_log_is_bounded_by_bytes(tmp_path: Path) -> None:
    bound = SEGMENTS * 64 * 1024
    log = SourceLog(tmp_path, max_bytes=bound)
    payload = b"p" * 4096
    for i in range(2000):  # 8 MB in: 16 times the bound
        log.append("r/camera", i, payload, "application/msgpack")
    log.close()
    total = sum(p.stat().st_size for p in log.segments())
    assert total <= bound + bound // SEGMENTS  # the open segment may be full
    stamps = [s for _, s, _, _ in log.since({"r/camera": 0})]
    assert stamps == list(range(stamps[0], 2000)) and stamps[0] > 0  # the newest, in order


def test_a_file_cut_short_gives_what_it_holds(tmp_path: Path) -> None:
    log = SourceLog(tmp_path, max_bytes=SEGMENTS * 64 * 1024, flush_s=0.0)
    for i in range(50):
        log.append("r/skeleton", i, b"y" * 100, "application/msgpack")
    log.close()
    (path,) = log.segments()
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    stamps = [
        s
        for _, s, _, _ in SourceLog(tmp_path, max_bytes=SEGMENTS * 64 * 1024).since(
            {"r/skeleton": 0}
        )
    ]
    assert 0 < len(stamps) < 50 and stamps == list(range(len(stamps)))


def test_a_log_too_small_to_hold_anything_is_refused(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="valid: at least"):
        SourceLog(tmp_path, max_bytes=1000)


async def frames() -> AsyncIterator[tuple[str, dict[str, tuple[float, float, float]]]]:
    """A live plug-in source (services.plugins): 30 skeleton frames."""
    for i in range(30):
        yield "skeleton", {"right_hand": (0.1 * i, 0.0, 0.5), "torso": (0.0, 0.0, 0.0)}
        await asyncio.sleep(0)


async def test_a_live_ingest_logs_what_it_publishes_and_a_successor_plays_it_again(
    tmp_path: Path,
) -> None:
    config = private_config()
    with Bus.open(config) as bus:
        sub = bus.subscribe(bus.keys.skeleton, s.SkeletonFrame, SKELETON)
        ingest = SensorIngest(plugin="test_source_log:frames", state=str(tmp_path), bus=bus)
        task = asyncio.create_task(ingest.run(install_signals=False))
        try:
            await asyncio.wait_for(ingest.finished.wait(), 30)
        finally:
            ingest.stop()
            await asyncio.wait_for(task, 10)
        got = [await asyncio.wait_for(sub.recv(), 10) for _ in range(30)]
        stamps = [r.message.header.stamp for r in got]
        log = SourceLog(tmp_path, max_bytes=SEGMENTS * 64 * 1024)
        logged = list(log.since({bus.keys.skeleton: 0}))
        assert [stamp for _, stamp, _, _ in logged] == stamps
        assert [p for _, _, p, _ in logged] == [s.encode(r.message) for r in got]
        # a successor publishing from the log, from the 21st frame on
        pub = bus.publisher(bus.keys.skeleton, s.SkeletonFrame, SKELETON)
        log.record([pub])
        assert log.play_again({bus.keys.skeleton: stamps[20]}) == 10
        again = [await asyncio.wait_for(sub.recv(), 10) for _ in range(10)]
        assert [r.message for r in again] == [r.message for r in got[20:]]
        assert len(list(log.since({bus.keys.skeleton: 0}))) == 30  # not logged twice
        pub.close()
        sub.close()
