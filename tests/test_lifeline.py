"""A child dies with its supervisor, whatever killed the supervisor (runtime.process.lifeline,
issue 39)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

from beyond_self.runtime.process import lifeline

REPO = Path(__file__).resolve().parent.parent
CHILD = """
import sys, time
from beyond_self.runtime.process import lifeline
lifeline.bind()
print("bound", flush=True)
for line in sys.stdin:  # answers each ping, so the supervisor knows it is alive
    print("pong", flush=True)
time.sleep(600)
"""
SUPERVISOR = """
import os, subprocess, sys, threading
from beyond_self.runtime.process import lifeline
CHILD = {child!r}

def start():
    env = {{**os.environ, **lifeline.child_env()}}
    return subprocess.Popen([sys.executable, "-c", CHILD], env=env, stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True, start_new_session=True)

if {from_thread!r}:  # started by a thread that ends while the supervisor goes on
    box = []
    thread = threading.Thread(target=lambda: box.append(start()))
    thread.start()
    thread.join()
    child = box[0]
else:
    child = start()
assert child.stdout.readline() == "bound\\n"
child.stdin.write("ping\\n")
child.stdin.flush()
print(child.pid, child.stdout.readline().strip(), flush=True)
sys.stdin.read()  # until the test kills us
"""


def gone(pid: int) -> bool:
    """No such process, or only its zombie (dead, not yet reaped by whoever adopted it)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return True
    return stat.rsplit(")", 1)[1].split()[0] == "Z"


def wait_gone(pids: list[int], bound_s: float) -> list[int]:
    """The pids of `pids` still alive after polling for at most `bound_s` seconds."""
    deadline = time.monotonic() + bound_s
    alive = list(pids)
    while alive and time.monotonic() < deadline:
        alive = [p for p in alive if not gone(p)]
        time.sleep(0.02)
    return [p for p in alive if not gone(p)]


def env() -> dict[str, str]:
    path = os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])
    return {**os.environ, "PYTHONPATH": path}


def start_supervisor(from_thread: bool) -> tuple[subprocess.Popen[str], int]:
    script = textwrap.dedent(SUPERVISOR).format(child=CHILD, from_thread=from_thread)
    supervisor = subprocess.Popen(
        [sys.executable, "-c", script], env=env(), stdin=subprocess.PIPE,
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert supervisor.stdout is not None
    pid, answer = supervisor.stdout.readline().split()
    assert answer == "pong"  # alive: with a thread, after the thread that started it ended
    return supervisor, int(pid)


def killed_then(supervisor: subprocess.Popen[str], child: int) -> list[int]:
    """SIGKILL the supervisor; its children still alive a second later (killed then, so that
    a failing test leaves nothing behind)."""
    assert not gone(child)
    supervisor.send_signal(signal.SIGKILL)
    supervisor.wait()
    left = wait_gone([child], 1.0)
    for pid in left:
        os.kill(pid, signal.SIGKILL)
    return left


def test_a_child_dies_within_a_second_of_its_supervisor_killed_with_sigkill() -> None:
    supervisor, child = start_supervisor(from_thread=False)
    assert killed_then(supervisor, child) == []


def test_a_child_started_by_a_passing_thread_lives_on_then_dies_with_its_supervisor() -> None:
    """PR_SET_PDEATHSIG fires when the starting thread ends: such a child has the pidfd watch
    alone, which outlives the thread and still ends the child with the supervisor."""
    supervisor, child = start_supervisor(from_thread=True)
    assert killed_then(supervisor, child) == []


def test_a_child_whose_supervisor_died_before_it_bound_leaves_at_once() -> None:
    """The race: the parent ended before the child asked to die with it. The child's parent
    is then not the pid it was given, and it leaves with one line."""
    stranger = os.getppid()  # alive, and not the child's parent
    run = subprocess.run(
        [sys.executable, "-c", CHILD], env={**env(), lifeline.ENV: str(stranger)},
        input="", capture_output=True, text=True, timeout=30,
    )  # fmt: skip
    assert run.returncode == lifeline.ORPHANED
    assert run.stdout == ""
    assert run.stderr.strip().splitlines() == [
        f"beyond: the supervisor (pid {stranger}) that started this process is gone; "
        f"leaving ({lifeline.ENV})"
    ]


def test_bind_takes_the_variable_out_of_what_children_inherit() -> None:
    environ = {"PATH": "/bin", lifeline.ENV: "not a pid"}
    assert lifeline.bind(environ) is None
    assert environ == {"PATH": "/bin"}
    assert lifeline.bind({}) is None
    assert lifeline.child_env() == {lifeline.ENV: str(os.getpid())}  # pytest's main thread
