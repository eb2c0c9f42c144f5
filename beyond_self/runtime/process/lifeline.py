"""A child process dies with its supervisor, whatever ended the supervisor (SIGKILL included).

The supervisor names itself in the child's environment (`child_env`); the child, first thing
(`bind`: the `beyond` entry point, the frame describer's worker), asks Linux to SIGKILL it when
that parent ends (PR_SET_PDEATHSIG), then checks that its parent is still that process: one that
died before the request was made left an orphan the request cannot catch. A second line, a
thread waiting on the parent's pidfd, kills the child's process group when the parent ends.
PR_SET_PDEATHSIG fires when the *thread* that started the child ends, so a supervisor asks for
it only from its main thread; a child started from another thread has the pidfd watch alone.
"""

from __future__ import annotations

import contextlib
import os
import select
import signal
import sys
import threading
import time
from collections.abc import MutableMapping

ENV = "BEYOND_SUPERVISOR"  # "<pid>", or "<pid>/process": started by a thread other than main
PR_SET_PDEATHSIG = 1  # linux/prctl.h
ORPHANED = 1  # exit status of a child whose supervisor was gone before it could bind to it
POLL_S = 0.2  # where there is no pidfd: how often the parent's presence is checked


def child_env() -> dict[str, str]:
    """What a supervisor adds to a child's environment for the child to `bind` to it, from the
    thread that is about to start the child."""
    main = threading.current_thread() is threading.main_thread()
    return {ENV: str(os.getpid()) + ("" if main else "/process")}


def bind(environ: MutableMapping[str, str] | None = None) -> int | None:
    """Tie this process's life to the supervisor its environment names (none: nothing to do);
    the supervisor's pid. The variable is removed, so what this process starts in turn is not
    bound to a process that is not its parent."""
    environ = os.environ if environ is None else environ
    value = environ.pop(ENV, None)
    if value is None:
        return None
    text, _, how = value.partition("/")
    if not text.isdigit():
        return None  # not ours to judge: a supervisor always writes a pid
    parent = int(text)
    if how != "process":
        _pdeathsig(signal.SIGKILL)
    pidfd = _pidfd(parent)
    if os.getppid() != parent:
        print(
            f"beyond: the supervisor (pid {parent}) that started this process is gone; "
            f"leaving ({ENV})",
            file=sys.stderr,
            flush=True,
        )
        os._exit(ORPHANED)
    threading.Thread(target=_outlive, args=(parent, pidfd), name="lifeline", daemon=True).start()
    return parent


def _pdeathsig(sig: signal.Signals) -> bool:
    """Ask the kernel for `sig` when our parent (thread) ends; False where there is no prctl."""
    if not sys.platform.startswith("linux"):
        return False
    import ctypes.util  # here: every `beyond` command binds, few have a supervisor

    libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
    return bool(libc.prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0) == 0)


def _pidfd(pid: int) -> int | None:
    opener = getattr(os, "pidfd_open", None)
    if opener is None:
        return None
    try:
        fd: int = opener(pid)
    except OSError:  # gone already (the check after it says so), or not allowed
        return None
    return fd


def _outlive(parent: int, pidfd: int | None) -> None:
    """Wait for the parent to end, then end this process and its group (what it started)."""
    if pidfd is not None:
        select.select([pidfd], [], [])  # readable once the parent has ended
    else:
        while os.getppid() == parent:
            time.sleep(POLL_S)
    if os.getpgrp() == os.getpid():  # leader of its own group: what it started goes too
        with contextlib.suppress(OSError):
            os.killpg(os.getpgrp(), signal.SIGKILL)
    os.kill(os.getpid(), signal.SIGKILL)
