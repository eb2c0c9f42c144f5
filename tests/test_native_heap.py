"""runtime.process.native_heap: a service process gives the C allocator's free memory back to
the system while it runs (glibc keeps all but an arena's top resident otherwise)."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from beyond_self.runtime.process import native_heap

pytestmark = pytest.mark.skipif(
    native_heap._malloc_trim() is None, reason="the C library has no malloc_trim (not glibc)"
)


def _rss_mb() -> float:
    status = Path("/proc/self/status").read_text()
    return int(next(x for x in status.splitlines() if x.startswith("VmRSS")).split()[1]) / 1024


def _freed_below_a_live_block(mb: int) -> list[bytes]:
    """`mb` MB allocated on a thread of its own (its own arena, as Zenoh's threads have) in
    1 KB blocks (above pymalloc's limit: the C allocator's), then all freed but the last, which
    keeps glibc from giving the rest back by itself; the survivor is returned."""
    kept: list[bytes] = []

    def work() -> None:
        blocks = [bytes(1024) + bytes([i % 251]) for i in range(mb * 1024)]
        kept.append(blocks[-1])
        del blocks

    thread = threading.Thread(target=work)
    thread.start()
    thread.join()
    return kept


def test_the_trimming_thread_gives_free_memory_back() -> None:
    kept = _freed_below_a_live_block(48)
    before = _rss_mb()
    stop = native_heap.start_trimming(every_s=0.02)
    try:
        deadline = time.monotonic() + 5.0
        while _rss_mb() > before - 24 and time.monotonic() < deadline:
            time.sleep(0.02)
    finally:
        stop()
    assert _rss_mb() <= before - 24, f"resident {_rss_mb():.0f} MB, {before:.0f} MB before"
    assert kept


def test_a_trim_now_says_it_trimmed() -> None:
    assert native_heap.trim() is True
