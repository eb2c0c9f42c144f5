"""Runs `beyond` command lines for tests/test_cli_hostile.py, each in a fork of one warm process.

Why a separate process that forks: a case must be cheap (thousands run in CI), so the commands'
modules are imported once here; each case still needs isolation (a hang must be killable, a
crash or an exit must not take the test run with it, a Zenoh session must not outlive it). The
pytest process itself may hold Zenoh sessions of other tests, whose threads a fork would not
carry over, so it never forks: it talks to this worker over pipes.

Protocol: one JSON object a line on stdin, {"argv": [...], "timeout": seconds}; one JSON object a
line on stdout per case: {"rc": int | null, "hung": bool, "stdout": str, "stderr": str}.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import tempfile
import time
import traceback
from typing import Any

LIMIT = 8192  # characters of each output stream sent back


def _child(argv: list[str], out_fd: int, err_fd: int) -> None:
    os.setsid()  # its own process group: a timeout kills whatever it started too
    devnull = os.open(os.devnull, os.O_RDONLY)
    os.dup2(devnull, 0)
    os.dup2(out_fd, 1)
    os.dup2(err_fd, 2)
    sys.stdout = open(1, "w", encoding="utf-8", errors="replace", closefd=False)  # noqa: SIM115
    sys.stderr = open(2, "w", encoding="utf-8", errors="replace", closefd=False)  # noqa: SIM115
    signal.signal(signal.SIGINT, signal.default_int_handler)
    from beyond_self.cli import main

    code = 1
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's exits
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except BaseException:  # a traceback is what the test looks for
        traceback.print_exc()
        code = 1
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    finally:
        os._exit(code)


def _read(fd: int) -> str:
    os.lseek(fd, 0, os.SEEK_SET)
    data = os.read(fd, LIMIT * 4)
    return data.decode("utf-8", "replace")[:LIMIT]


def run_case(argv: list[str], timeout: float) -> dict[str, Any]:
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        pid = os.fork()
        if pid == 0:
            _child(argv, out.fileno(), err.fileno())
        deadline = time.monotonic() + timeout
        status: int | None = None
        pause = 0.001
        while status is None:
            done, st = os.waitpid(pid, os.WNOHANG)
            if done:
                status = st
                break
            if time.monotonic() > deadline:
                break
            time.sleep(pause)
            pause = min(pause * 2, 0.02)
        hung = status is None
        if hung:
            for sig in (signal.SIGINT, signal.SIGKILL):
                try:
                    os.killpg(pid, sig)
                except ProcessLookupError:
                    break
                time.sleep(0.5)
            _, status = os.waitpid(pid, 0)
        rc = None if hung else os.waitstatus_to_exitcode(status)  # type: ignore[arg-type]
        return {
            "rc": rc,
            "hung": hung,
            "stdout": _read(out.fileno()),
            "stderr": _read(err.fileno()),
        }


def main() -> None:
    import beyond_self.cli

    beyond_self.cli.build_parser()  # imports every command module once, before any fork
    print(json.dumps({"ready": True}), flush=True)
    for line in sys.stdin:
        case = json.loads(line)
        print(json.dumps(run_case(case["argv"], float(case["timeout"]))), flush=True)


if __name__ == "__main__":
    main()
