"""Start services as separate processes, stream their logs with their names, stop them cleanly.

Each service runs as `python -P -m beyond_self service NAME` with the bus settings in its
environment, exactly as on another machine (`-P`: a stray `beyond_self/` in the current folder
cannot replace our code). One started `held` imports what it runs, then waits off the bus for
`release` (a line on its stdin). Output is read in chunks, not lines: a line over asyncio's 64 KiB
readline limit would end a line reader, and the service would then block on a full pipe.
`HealthWatch` stops a service that leaves STUCK_AFTER health queries in a row unanswered.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import sys
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from beyond_self.runtime.bus.config import ENV_VARS, BusConfig
from beyond_self.runtime.process import lifeline
from beyond_self.schemas.keys import Keys

if TYPE_CHECKING:
    from beyond_self.runtime.bus.session import Bus

LogSink = Callable[[str, str], None]
LINE_MAX = 4096  # characters of one log line passed on (the rest is counted, not kept)
LINES_KEPT = 1000  # last lines of each service kept in memory
HEALTH_TIMEOUT_S = 10.0  # a health query unanswered this long is a miss (a busy loop answers)
STUCK_AFTER = 3  # misses in a row: the service is stuck
HELD_ENV = "BEYOND_HELD"  # set in a child started held: it waits for `release` on its stdin
RELEASE = b"go\n"


@dataclass
class ServiceProcess:
    name: str  # in its deployment: the service's, or a shard's (`gestures.shard1`)
    process: asyncio.subprocess.Process
    reader: asyncio.Task[None] | None = None
    lines: deque[str] = field(default_factory=lambda: deque(maxlen=LINES_KEPT))
    stuck: bool = False
    held: bool = False  # started, waiting for `release` before it joins the bus
    service: str = ""  # the service it runs ("": its name)
    robot: str = ""  # whose keys it is alive and answers health on ("": its deployment's)

    @property
    def running(self) -> bool:
        return self.process.returncode is None

    def alive_key(self, keys: Keys) -> str:
        """Its liveliness token, `keys` being its deployment's."""
        return Keys(self.robot or keys.robot).alive(self.service or self.name)

    def health_key(self, keys: Keys) -> str:
        return Keys(self.robot or keys.robot).health(self.service or self.name)


def service_env(config: BusConfig, extra: Mapping[str, str] | None = None) -> dict[str, str]:
    """The environment that makes a child join `config`'s group: ours, with every bus variable
    replaced by `config`'s own (`config` is authoritative: what it leaves unset must not leak in
    from our environment). Identity is left out: each child presents its own certificate."""
    env = {k: v for k, v in os.environ.items() if k not in ENV_VARS}
    env.update(config.with_(identity=None).to_env())
    env.setdefault("BEYOND_LOG_FORMAT", "text")
    env["PYTHONUNBUFFERED"] = "1"
    env.update(extra or {})
    return env


BEYOND = (sys.executable, "-P", "-m", "beyond_self")
"""The `beyond` command as a child process runs it: this interpreter, the current folder off the
import path (-P)."""


async def start_service(
    name: str,
    env: Mapping[str, str],
    *,
    config_file: str | None = None,
    options: Mapping[str, Any] | None = None,
    sink: LogSink | None = None,
    command: list[str] | None = None,
    held: bool = False,
    service: str = "",
    robot: str = "",
) -> ServiceProcess:
    """Start service `name` (or, with `command`, `beyond COMMAND...` under that name); `held`:
    it waits for `release` before it joins the bus. `service` and `robot`: what it runs and
    whose keys it is alive on, when not its name and its deployment's (a shard)."""
    import json

    cmd = [*BEYOND, *(command or ["service", name])]
    if config_file:
        cmd += ["--config", config_file]
    for key, value in (options or {}).items():
        cmd += ["--set", f"{key}={json.dumps(value)}"]
    proc = await asyncio.create_subprocess_exec(  # started from this thread: the event loop's
        *cmd,
        # it dies with us (runtime.process.lifeline)
        env={**env, **lifeline.child_env(), **({HELD_ENV: "1"} if held else {})},
        stdin=asyncio.subprocess.PIPE if held else asyncio.subprocess.DEVNULL,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.STDOUT,
        start_new_session=True,  # Ctrl-C in the terminal reaches `up`, which stops us cleanly
    )
    sp = ServiceProcess(name, proc, held=held, service=service, robot=robot)

    def line(text: str) -> None:
        sp.lines.append(text)
        if sink is not None:
            sink(name, text)

    assert proc.stdout is not None
    sp.reader = asyncio.get_running_loop().create_task(read_lines(proc.stdout, line))
    return sp


def release(sp: ServiceProcess) -> None:
    """Let a process started held join the bus (nothing for one that is not held). One that
    died meanwhile is not written to: its exit is for the supervisor to see."""
    if not sp.held:
        return
    sp.held = False
    stdin = sp.process.stdin
    if stdin is None:
        return
    if sp.running:
        with contextlib.suppress(ConnectionError):  # it died just now
            stdin.write(RELEASE)
    stdin.close()


def wait_for_release() -> bool:
    """In a process started held (HELD_ENV set): wait until the supervisor releases it (True),
    or lets it go without (False: its stdin ends first). True at once in any other process.
    The variable is removed, so what this process starts is not held in turn."""
    if os.environ.pop(HELD_ENV, None) is None or sys.stdin is None:
        return True
    return sys.stdin.buffer.readline() == RELEASE


async def read_lines(stream: asyncio.StreamReader, on_line: Callable[[str], None]) -> None:
    """Pass each line of `stream` to `on_line`, decoded leniently and cut to LINE_MAX characters,
    until end of file. Reads in chunks so no line is too long and the writer never blocks on a
    full pipe because we stopped reading."""
    pending = bytearray()
    dropped = 0  # bytes of the current line beyond what is kept

    def emit(raw: bytes | bytearray, extra: int) -> None:
        text = bytes(raw).decode("utf-8", "replace").rstrip()
        if extra or len(text) > LINE_MAX:
            total = len(raw) + extra
            text = f"{text[:LINE_MAX]}... (line of {total} bytes cut)"
        on_line(text)

    while True:
        chunk = await stream.read(1 << 16)
        if not chunk:
            break
        pending += chunk
        while (end := pending.find(b"\n")) >= 0:
            emit(pending[:end], dropped)
            del pending[: end + 1]
            dropped = 0
        if len(pending) > 4 * LINE_MAX:  # a very long line: keep its start, count the rest
            dropped += len(pending) - 4 * LINE_MAX
            del pending[4 * LINE_MAX :]
    if pending or dropped:
        emit(pending, dropped)


def kill_group(sp: ServiceProcess) -> None:
    """SIGKILL what is left of a dead service's process group (it was started in a session of
    its own): a child it started, a speech synthesizer, must not outlive it."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(sp.process.pid, signal.SIGKILL)


async def stop_stuck(sp: ServiceProcess, grace: float = 2.0) -> int:
    """Stop a service that no longer answers: SIGTERM (and SIGCONT, should it be stopped), then
    SIGKILL after `grace` s, since a blocked event loop may never run its signal handler."""
    for sig in (signal.SIGTERM, signal.SIGCONT):
        with contextlib.suppress(ProcessLookupError):
            sp.process.send_signal(sig)
    try:
        return await asyncio.wait_for(sp.process.wait(), grace)
    except TimeoutError:
        with contextlib.suppress(ProcessLookupError):
            sp.process.kill()
        return await sp.process.wait()


class HealthWatch:
    """Asks every running service for its health every `period` s; a service that misses
    `stuck_after` answers in a row is reported (`on_stuck(name, why)`), marked stuck and stopped.

    Why a query and not the periodic health messages: the query is answered on the service's
    event loop, so it fails exactly when the service is frozen (blocked on a full pipe, a long
    computation, a stopped process), while the process still looks alive to the OS."""

    def __init__(
        self,
        bus: Bus,
        processes: list[ServiceProcess],
        on_stuck: Callable[[str, str], None],
        *,
        period: float = 2.0,
        timeout: float = HEALTH_TIMEOUT_S,
        stuck_after: int = STUCK_AFTER,
    ) -> None:
        self.bus, self.processes, self.on_stuck = bus, processes, on_stuck
        self.period, self.timeout, self.stuck_after = period, timeout, stuck_after
        self.misses: dict[str, int] = {}
        self.answered: dict[str, int] = {}
        self._task: asyncio.Task[None] | None = None

    def start(self) -> None:
        self._task = asyncio.get_running_loop().create_task(self._run())

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task

    async def check(self, sp: ServiceProcess) -> None:
        from beyond_self.schemas import ServiceHealth

        key = sp.health_key(self.bus.keys)
        try:
            replies = await self.bus.query(key, ServiceHealth, timeout=self.timeout)
        except Exception:  # a malformed reply is no answer either
            replies = []
        if replies:
            self.misses[sp.name] = 0
            self.answered[sp.name] = self.answered.get(sp.name, 0) + 1
            return
        self.misses[sp.name] = misses = self.misses.get(sp.name, 0) + 1
        if misses >= self.stuck_after and sp.running and not sp.stuck:
            sp.stuck = True
            why = f"no health answer to {misses} queries of {self.timeout:g} s in a row"
            self.on_stuck(sp.name, why)
            await stop_stuck(sp)

    async def _run(self) -> None:
        while True:
            running = [sp for sp in self.processes if sp.running and not sp.stuck]
            await asyncio.gather(*(self.check(sp) for sp in running))
            await asyncio.sleep(self.period)


async def stop_services(processes: list[ServiceProcess], timeout: float = 60.0) -> dict[str, int]:
    """SIGTERM every running service, SIGKILL those still running after `timeout`. The timeout
    is generous on purpose: on a loaded machine a healthy service can take seconds to close its
    session, and killing it then would be reported as an unclean stop; only a hung one waits
    that long."""
    for sp in processes:
        if sp.running:
            with contextlib.suppress(ProcessLookupError):
                sp.process.send_signal(signal.SIGTERM)
    codes: dict[str, int] = {}
    for sp in processes:
        try:
            codes[sp.name] = await asyncio.wait_for(sp.process.wait(), timeout)
        except TimeoutError:
            with contextlib.suppress(ProcessLookupError):
                sp.process.kill()
            codes[sp.name] = await sp.process.wait()
        if sp.reader is not None:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(sp.reader, 2.0)
    return codes
