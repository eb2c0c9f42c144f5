"""Start services as separate processes, stream their logs with their names, stop them cleanly.

Each service runs as `python -m beyond service NAME` with the bus settings in its environment,
exactly as it would on another machine, so `beyond up` exercises the real deployment path.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from runtime.config import BusConfig

LogSink = Callable[[str, str], None]


@dataclass
class ServiceProcess:
    name: str
    process: asyncio.subprocess.Process
    reader: asyncio.Task[None] | None = None
    lines: list[str] = field(default_factory=list)

    @property
    def running(self) -> bool:
        return self.process.returncode is None


def service_env(config: BusConfig, extra: Mapping[str, str] | None = None) -> dict[str, str]:
    """The environment that makes a child join `config`'s group."""
    env = dict(os.environ)
    listen, _ = config.endpoints()
    env.update(
        BEYOND_ROBOT=config.robot,
        BEYOND_ZENOH_MODE=config.mode,
        BEYOND_ZENOH_PORT=str(config.port),
        BEYOND_LOG_FORMAT=env.get("BEYOND_LOG_FORMAT", "text"),
        PYTHONUNBUFFERED="1",
    )
    # `config` is authoritative: what it leaves unset must not leak in from our own environment
    for name in ("BEYOND_ZENOH_CONNECT", "BEYOND_ZENOH_LISTEN", "BEYOND_ZENOH_CONFIG"):
        env.pop(name, None)
    env.pop("BEYOND_ZENOH_ROUTER", None)
    if config.connect is not None:
        env["BEYOND_ZENOH_CONNECT"] = ",".join(config.connect)
    if config.listen is not None:
        env["BEYOND_ZENOH_LISTEN"] = ",".join(listen)
    if config.config_file is not None:
        env["BEYOND_ZENOH_CONFIG"] = str(config.config_file)
    if config.routers:
        env["BEYOND_ZENOH_ROUTER"] = ",".join(config.routers)
    env.pop("BEYOND_ZENOH_SECURE", None)
    env.pop("BEYOND_ZENOH_IDENTITY", None)  # each child presents its own certificate
    if config.secure is not None:
        env["BEYOND_ZENOH_SECURE"] = str(config.secure)
    env.update(extra or {})
    return env


async def start_service(
    name: str,
    env: Mapping[str, str],
    *,
    config_file: str | None = None,
    options: Mapping[str, Any] | None = None,
    sink: LogSink | None = None,
    command: list[str] | None = None,
) -> ServiceProcess:
    """Start service `name` (or, with `command`, `beyond COMMAND...` under that name)."""
    import json

    cmd = [sys.executable, "-m", "beyond", *(command or ["service", name])]
    if config_file:
        cmd += ["--config", config_file]
    for key, value in (options or {}).items():
        cmd += ["--set", f"{key}={json.dumps(value)}"]
    proc = await asyncio.create_subprocess_exec(
        *cmd,
        env=dict(env),
        stdin=asyncio.subprocess.DEVNULL,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.STDOUT,
        start_new_session=True,  # Ctrl-C in the terminal reaches `up`, which stops us cleanly
    )
    sp = ServiceProcess(name, proc)

    async def read() -> None:
        assert proc.stdout is not None
        async for raw in proc.stdout:
            line = raw.decode("utf-8", "replace").rstrip()
            sp.lines.append(line)
            if sink is not None:
                sink(name, line)

    sp.reader = asyncio.get_running_loop().create_task(read())
    return sp


async def stop_services(processes: list[ServiceProcess], timeout: float = 8.0) -> dict[str, int]:
    """SIGTERM every running service, SIGKILL those still running after `timeout`."""
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
