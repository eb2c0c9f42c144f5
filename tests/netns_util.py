"""Two "hosts" on one machine: Linux network namespaces joined by a veth pair.

`TwoHosts` creates namespaces `bxdeploy-<pid>-<tag>-robot` / `-ws`, a veth pair between them with
private addresses (10.x.y.1 and .2, which exist only inside these namespaces), runs processes in
either with `ip netns exec`, and cuts and restores the link. `close()` kills every process it
started (by process group, then anything still inside the namespaces, by pid) and deletes the
namespaces (which deletes the veth pair). Namespaces left by a run that was killed outright are
removed: a reaper process outside the test's process tree cleans up as soon as the test process
is gone, the processes started directly also get SIGKILL then (PR_SET_PDEATHSIG), and the next
run removes anything still left (names carry the creating pid; a dead pid means stale).

Run as a script, this module is the test's probe: `python tests/netns_util.py probe` joins the
bus from the environment and prints one JSON line per event it sees (see `probe`).
"""

from __future__ import annotations

import contextlib
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

PREFIX = "bxdeploy"
REPO = Path(__file__).resolve().parent.parent


def unavailable() -> str | None:
    """Why the namespace test cannot run here, or None."""
    if not sys.platform.startswith("linux"):
        return "network namespaces need Linux"
    if os.geteuid() != 0:
        return "creating network namespaces needs root (CI runs as root)"
    if shutil.which("ip") is None:
        return "the `ip` command (iproute2) is not installed"
    probe = f"{PREFIX}-{os.getpid()}-probe"
    try:
        _ip("netns", "add", probe)
    except (subprocess.CalledProcessError, OSError) as exc:
        return f"`ip netns add` does not work here: {exc}"
    finally:
        with contextlib.suppress(Exception):
            _ip("netns", "delete", probe)
    return None


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["ip", *args], check=check, capture_output=True, text=True, timeout=20)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _die_with_parent() -> None:
    """In the child before exec: SIGKILL it if the test process dies without cleaning up."""
    import ctypes

    pr_set_pdeathsig = 1
    with contextlib.suppress(Exception):
        ctypes.CDLL(None, use_errno=True).prctl(pr_set_pdeathsig, signal.SIGKILL)


def _kill_inside(ns: str) -> None:
    """SIGKILL every process still running inside namespace `ns` (they are ours: we made it)."""
    out = _ip("netns", "pids", ns, check=False).stdout.split()
    for pid in out:
        with contextlib.suppress(ProcessLookupError, ValueError):
            os.kill(int(pid), signal.SIGKILL)


def _start_reaper(namespaces: list[str]) -> subprocess.Popen[bytes]:
    """A watchdog outside the test's process tree: if the test process dies without cleaning
    up (SIGKILL), it kills everything left inside our namespaces (including grandchildren such
    as the services `beyond up` started) and deletes them; it exits once they are gone."""
    code = (
        "import os, subprocess, sys, time\n"
        "sys.path.insert(0, sys.argv[1])\n"
        "from netns_util import _alive, _ip, _kill_inside\n"
        "owner, names = int(sys.argv[2]), sys.argv[3:]\n"
        "while True:\n"
        "    listed = _ip('netns', 'list', check=False).stdout\n"
        "    if not any(n in listed.split() for n in names):\n"
        "        break\n"
        "    if not _alive(owner):\n"
        "        for n in names:\n"
        "            _kill_inside(n)\n"
        "            _ip('netns', 'delete', n, check=False)\n"
        "        break\n"
        "    time.sleep(0.5)\n"
    )
    here = str(Path(__file__).resolve().parent)
    return subprocess.Popen(
        [sys.executable, "-P", "-c", code, here, str(os.getpid()), *namespaces],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )


def remove_stale() -> list[str]:
    """Delete namespaces of earlier runs whose process is gone (a run killed with SIGKILL)."""
    removed = []
    listing = _ip("netns", "list", check=False).stdout
    for line in listing.splitlines():
        name = line.split()[0] if line.split() else ""
        m = re.fullmatch(rf"{PREFIX}-(\d+)-.*", name)
        if m and not _alive(int(m.group(1))):
            _kill_inside(name)
            _ip("netns", "delete", name, check=False)
            removed.append(name)
    return removed


@dataclass
class Proc:
    name: str
    popen: subprocess.Popen[str]
    lines: list[tuple[float, str]] = field(default_factory=list)
    on_line: Callable[[float, str], None] | None = None
    reader: threading.Thread | None = None

    def text(self) -> str:
        return "\n".join(line for _, line in self.lines)


class TwoHosts:
    """A robot namespace and a workstation namespace joined by one veth link."""

    def __init__(self) -> None:
        remove_stale()
        tag = f"{random.randrange(16**4):04x}"
        self.robot = f"{PREFIX}-{os.getpid()}-{tag}-robot"
        self.ws = f"{PREFIX}-{os.getpid()}-{tag}-ws"
        self.veth_robot, self.veth_ws = f"bxr{tag}", f"bxw{tag}"  # <= 15 characters
        net = random.randrange(1, 250)
        self.robot_ip, self.ws_ip = f"10.213.{net}.1", f"10.213.{net}.2"
        self.procs: list[Proc] = []
        self._created: list[str] = []
        try:
            for ns in (self.robot, self.ws):
                _ip("netns", "add", ns)
                self._created.append(ns)
                _ip("-n", ns, "link", "set", "lo", "up")
            # created directly inside the namespaces: the host's own network is never touched
            _ip(
                "link", "add", self.veth_robot, "netns", self.robot, "type", "veth",
                "peer", "name", self.veth_ws, "netns", self.ws,
            )  # fmt: skip
            _ip("-n", self.robot, "addr", "add", f"{self.robot_ip}/30", "dev", self.veth_robot)
            _ip("-n", self.ws, "addr", "add", f"{self.ws_ip}/30", "dev", self.veth_ws)
            self.link(up=True)
            self._reaper = _start_reaper(self._created)
        except BaseException:
            self.close()
            raise

    def link(self, *, up: bool) -> None:
        """Bring both ends of the link up or down (down: every packet between the hosts is lost,
        the TCP connections across stay open until Zenoh's lease gives up on them)."""
        state = "up" if up else "down"
        _ip("-n", self.robot, "link", "set", self.veth_robot, state)
        _ip("-n", self.ws, "link", "set", self.veth_ws, state)

    def start(
        self,
        ns: str,
        name: str,
        argv: Sequence[str],
        env: dict[str, str],
        on_line: Callable[[float, str], None] | None = None,
    ) -> Proc:
        """Run `argv` inside namespace `ns`; its stdout+stderr lines are kept with arrival time."""
        popen = subprocess.Popen(
            ["ip", "netns", "exec", ns, *argv],
            env=env,
            cwd=str(REPO),
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            bufsize=1,
            start_new_session=True,  # its own process group: killed as one in close()
            preexec_fn=_die_with_parent,
        )
        proc = Proc(name, popen, on_line=on_line)

        def read() -> None:
            assert popen.stdout is not None
            for raw in popen.stdout:
                now = time.monotonic()
                line = raw.rstrip("\n")
                proc.lines.append((now, line))
                if proc.on_line is not None:
                    proc.on_line(now, line)

        proc.reader = threading.Thread(target=read, name=f"read-{name}", daemon=True)
        proc.reader.start()
        self.procs.append(proc)
        return proc

    def stop(self, proc: Proc, timeout: float = 15.0) -> int:
        """SIGTERM the process group, SIGKILL after `timeout`; the exit status."""
        if proc.popen.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.popen.pid, signal.SIGTERM)
        try:
            code = proc.popen.wait(timeout)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.popen.pid, signal.SIGKILL)
            code = proc.popen.wait(10)
        if proc.reader is not None:
            proc.reader.join(5)
        return code

    def close(self) -> None:
        for proc in reversed(self.procs):
            with contextlib.suppress(Exception):
                self.stop(proc, timeout=5)
        for ns in self._created:
            _kill_inside(ns)
            _ip("netns", "delete", ns, check=False)
        self._created.clear()
        reaper = getattr(self, "_reaper", None)
        if reaper is not None:  # it sees the namespaces gone and exits
            try:
                reaper.wait(5)
            except subprocess.TimeoutExpired:
                reaper.kill()
                reaper.wait(5)

    def namespaces_left(self) -> list[str]:
        listing = _ip("netns", "list", check=False).stdout
        names = {line.split()[0] for line in listing.splitlines() if line.split()}
        return sorted(names & {self.robot, self.ws})


# -- the probe ---------------------------------------------------------------------------------


def probe() -> int:
    """Print a JSON line for every gesture "end" event and final description on the bus.

    Gesture events are watched twice: by a plain subscriber (what arrives live) and by a
    recovering one (what the pipeline's services get, live or recovered from the robot's
    publisher cache). An end event only the recovering subscriber saw was recovered from the
    cache: that is how the test counts gestures recovered. Liveliness tokens of every service
    are reported too: the other side's vanish when Zenoh gives up on a cut link, and come back
    when the link does."""
    import asyncio
    import json

    import zenoh

    from beyond_self.runtime.bus.delivery import EVENTS
    from beyond_self.runtime.bus.session import Bus
    from beyond_self.schemas import Description, GestureSegment

    zenoh.init_log_from_env_or("error")  # RUST_LOG=zenoh=debug to see the transport's view

    lock = threading.Lock()  # Zenoh threads print too: one whole line at a time

    def say(**fields: object) -> None:
        line = json.dumps({"t": time.time(), **fields}) + "\n"
        with lock:
            sys.stdout.write(line)
            sys.stdout.flush()

    async def main() -> None:
        loop = asyncio.get_running_loop()
        stop = asyncio.Event()
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.add_signal_handler(sig, stop.set)
        with Bus.open() as bus:
            keys = bus.keys
            live = bus.subscribe(keys.gesture_segment, GestureSegment)
            recovering = bus.subscribe(keys.gesture_segment, GestureSegment, EVENTS)
            described = bus.subscribe(keys.description, Description, EVENTS)

            def on_token(sample: object) -> None:  # Zenoh thread; print is thread-safe enough
                kind = str(getattr(sample, "kind", ""))
                say(event="alive", key=str(getattr(sample, "key_expr", "")), kind=kind)

            token_sub = bus.session.liveliness().declare_subscriber(
                keys.alive("*"), on_token, history=True
            )

            async def pump(sub: object, via: str) -> None:
                async for received in sub:  # type: ignore[attr-defined]
                    msg = received.message
                    if isinstance(msg, GestureSegment):
                        if msg.event == "end":
                            say(event="end", via=via, segment=msg.segment_id)
                    elif msg.final and msg.sentences:
                        say(event="described", segment=msg.segment_id, text=msg.sentences[0].text)

            tasks = [
                loop.create_task(pump(live, "live")),
                loop.create_task(pump(recovering, "recovering")),
                loop.create_task(pump(described, "described")),
            ]
            say(event="probe-ready", zid=bus.zid)
            await stop.wait()
            for task in tasks:
                task.cancel()
            token_sub.undeclare()

    asyncio.run(main())
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    if sys.argv[1:] == ["probe"]:
        raise SystemExit(probe())
    raise SystemExit("usage: netns_util.py probe")
