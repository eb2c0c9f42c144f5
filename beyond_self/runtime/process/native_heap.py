"""The C allocator's free memory in a service process, handed back to the system now and then.

Zenoh's threads allocate each sample they receive in their own glibc arena; a backlog (a fleet's
robots starting together, a busy machine) fills those arenas, and once it is handled the memory
is free but stays resident: glibc gives back only the top of an arena. In a 32-robot gesture
streamer that was 23 MB, 0.75 MB per robot (docs/decisions.md). A thread of the process calls
glibc's `malloc_trim` every `TRIM_EVERY_S` (a few ms when there is much to give back, 0.05 ms
otherwise; it holds each arena's lock meanwhile, never the GIL). Elsewhere (musl, macOS) it does
nothing.
"""

from __future__ import annotations

import ctypes
import threading
from collections.abc import Callable

TRIM_EVERY_S = 5.0


def _malloc_trim() -> Callable[[int], int] | None:
    """glibc's `malloc_trim(pad)`, or None where the C library has none."""
    try:
        trim = ctypes.CDLL(None).malloc_trim
    except (AttributeError, OSError, TypeError):  # no such symbol, no C library handle
        return None
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return trim


def trim() -> bool:
    """Give the allocator's free pages back to the system now; whether it could."""
    fn = _malloc_trim()
    if fn is None:
        return False
    fn(0)
    return True


def start_trimming(every_s: float = TRIM_EVERY_S) -> Callable[[], None]:
    """Trim every `every_s` seconds on a daemon thread until the returned call stops it (a
    service process never stops it: it ends with the process). Nothing where there is no
    `malloc_trim`."""
    fn = _malloc_trim()
    stop = threading.Event()
    if fn is None:
        return stop.set

    def loop() -> None:
        while not stop.wait(every_s):
            fn(0)

    threading.Thread(target=loop, name="malloc-trim", daemon=True).start()
    return stop.set


M_TRIM_THRESHOLD = -1  # glibc's malloc.h
M_MMAP_THRESHOLD = -3


def keep_freed(largest: int) -> bool:
    """Keep freed blocks of up to `largest` bytes in the heap (glibc's `mallopt`: blocks that
    size come from the heap, not a mapping of their own, and up to four times it stays free at
    its top); whether it could. For a process that allocates and frees the same large arrays
    every frame: mapped afresh, each page of them faulted in again, 430 faults and a tenth of
    a frame's description (the frame describer's worker). `trim` still gives it all back."""
    try:
        fn = ctypes.CDLL(None).mallopt
    except (AttributeError, OSError, TypeError):
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_int]
    fn.restype = ctypes.c_int
    return bool(fn(M_MMAP_THRESHOLD, largest)) and bool(fn(M_TRIM_THRESHOLD, 4 * largest))
