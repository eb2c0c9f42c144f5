"""A service as a process: signals, the exit status, and leaving at once when done.

The submodules hold the rest of what a process is: its heap settled after set-up (`heap`) and
its bond to the supervisor that started it (`lifeline`)."""

from __future__ import annotations

import asyncio
import functools
import logging
import os
import signal
import sys
from collections.abc import Callable, Coroutine
from typing import Any, NoReturn

from beyond_self.core.errors import InputError
from beyond_self.runtime.log import setup_logging
from beyond_self.runtime.process import heap, native_heap


def install_signals(stop: Callable[[], None]) -> list[signal.Signals]:
    """SIGINT and SIGTERM call `stop`, where this thread may handle them; the ones installed."""
    loop = asyncio.get_running_loop()
    installed: list[signal.Signals] = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            loop.add_signal_handler(sig, stop)
            installed.append(sig)
        except (NotImplementedError, RuntimeError, ValueError):
            pass  # not the main thread, or not supported here
    return installed


# How long a thread may hold the GIL while another waits for it. A service's event loop is its
# one busy Python thread; Zenoh's threads take the GIL for a moment per sample (a callback) and
# the loop gives it up at every put and select. With CPython's 5 ms, at 96 robots the waiters
# forced the loop off mid-frame over and over: description p99 132-142 ms; with 20 ms 60-62 ms
# (bench/fleet.py rounds, same machine). 1 ms was no better than 5, 50 ms worse than 20.
SWITCH_INTERVAL_S = 0.02


@functools.cache  # once per process
def configure() -> None:
    """Set this process up as a service's own: logging, BLAS on one thread, the GIL's switch
    interval for one busy loop (`SWITCH_INTERVAL_S`), the heap settled after set-up
    (runtime.process.heap) and the C allocator's free memory given back (runtime.process.
    native_heap). Once; `run_to_completion` does it, a process started held
    (services.launcher) before it waits."""
    import numpy  # noqa: F401  (loads OpenBLAS, so the limit reaches it)
    from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]

    threadpool_limits(limits=1, user_api="blas")
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    heap.manage()
    native_heap.start_trimming()
    setup_logging()


def run_to_completion(work: Callable[[], Coroutine[Any, Any, None]]) -> int:
    """Run `work()` in a fresh event loop in a process set up as a service's (`configure`); 0,
    or 2 for bad input (one line logged, no traceback).

    Why one BLAS thread: a service is one event loop among the pipeline's processes, and its
    matrix products are small (the table model's upsampling, the network's factors). OpenBLAS's
    own threads spin while they wait for work, so on a loaded machine they take the cores the
    other services need: the object segmenter's per-frame description took 2 to 3 times longer
    beside three busy processes with them than without (bench/pipeline.py, stage costs)."""
    configure()
    try:
        asyncio.run(work())
    except InputError as exc:
        logging.getLogger("beyond").error(str(exc))
        return 2
    return 0


def exit_process(code: int) -> NoReturn:
    """Leave the process at once with `code`, logs and output flushed: for a process whose
    Zenoh session is closed and whose work is done (a service, `beyond up`). The interpreter's
    own teardown of native threads (Zenoh's, BLAS's) has been seen to abort such a process
    ("FATAL: exception not rethrown", SIGABRT) after it had stopped cleanly."""
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
