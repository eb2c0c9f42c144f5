"""The garbage collector's view of a service process: what set-up built stays out of its passes.

A service builds its long-lived state once and then allocates short-lived messages; CPython's
full collections walk every tracked object each time, and in a 64-robot fleet they paused the
reasoner's and describer's loops 36-41 ms mid-run (docs/decisions.md). So once a service (or a
fleet robot's run) is set up, the process collects once and freezes what survived (`gc.freeze`);
when a run ends its objects are unfrozen so the next settle frees its cycles. Reference counting
is untouched: only cycles wait for a settle.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import weakref

SETTLE_AFTER_S = 1.0  # a burst of robots joining settles once, not once per robot

_managed = False
_scheduled: weakref.WeakSet[asyncio.AbstractEventLoop] = weakref.WeakSet()


def manage() -> None:
    """This process is a service's own (runtime.process): settles take effect from now on.

    Only then: a process that hosts services among other work (a test run, a notebook) keeps
    the collector as it was, where a full collection at every service start would cost far more
    than it saves."""
    global _managed
    _managed = True


def settle_soon(delay_s: float = SETTLE_AFTER_S) -> None:
    """Collect and freeze the heap `delay_s` from now on the running loop, once however often
    it is asked in the meantime; nothing unless the process is `manage`d."""
    if not _managed:
        return
    loop = asyncio.get_running_loop()
    if loop in _scheduled:
        return
    _scheduled.add(loop)

    def settle() -> None:
        _scheduled.discard(loop)
        settle_now()

    loop.call_later(delay_s, settle)


def settle_now() -> None:
    """One full collection, then everything still alive leaves the collector's generations."""
    gc.collect()
    gc.freeze()


def release() -> None:
    """Hand frozen objects back to the collector (a run ended: its cycles may be garbage now),
    and settle again soon if a loop is running to do it."""
    if not _managed:
        return
    gc.unfreeze()
    with contextlib.suppress(RuntimeError):  # no running loop: the process is on its way out
        settle_soon()
