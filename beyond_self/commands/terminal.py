"""What the commands share for talking to a terminal: one progress bar style, and the stop event
that SIGINT/SIGTERM set so long-running commands end cleanly instead of with a traceback (and
with their summary, `run_until_stopped`)."""

from __future__ import annotations

import asyncio
import contextlib
import signal
import sys
from collections.abc import Awaitable, Callable
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn


class _Bar(Progress):
    """A progress bar that never stands before an error: erased when its block raises, and not
    drawn at all off a terminal (a log or a pipe would keep its last frame as a line)."""

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is not None:
            self.live.transient = True
        super().__exit__(exc_type, exc, tb)


def progress_bar(console: Console, *, transient: bool = True) -> Progress:
    """A bar with count, elapsed time and what is being done (on stderr when `console` is; the
    description last, so a long one never squeezes the numbers)."""
    return _Bar(
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("[bold]{task.description}"),
        console=console,
        transient=transient,
        disable=not console.is_terminal,
    )


def stop_on_signals() -> asyncio.Event:
    """An event set by SIGINT or SIGTERM (call from inside the running event loop)."""
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):
            loop.add_signal_handler(sig, stop.set)  # fails off the main thread
    return stop


def run_until_stopped(work: Callable[[asyncio.Event], Awaitable[str]]) -> int:
    """Run `work` with the stop event of `stop_on_signals` until it returns, then print what it
    returns, a summary of what it did, on stderr (stdout stays for data); exit status 0."""

    async def go() -> str:
        return await work(stop_on_signals())

    print(asyncio.run(go()), file=sys.stderr)
    return 0
