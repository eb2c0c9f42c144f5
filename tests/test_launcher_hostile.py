"""The launcher survives any output of a service, and reports and stops a stuck one (issue 16).

A 95 KB log line used to kill `beyond up`'s reader (asyncio's 64 KiB line limit); the pipe then
filled, the service blocked on its next write and answered nothing, while `up` still listed it
as running.
"""

from __future__ import annotations

import asyncio
import os
import signal
import sys
from pathlib import Path

import pytest
from busutil_net import env_for, private_config

from beyond_self.runtime.bus.session import Bus
from beyond_self.services.launcher import (
    LINE_MAX,
    HealthWatch,
    read_lines,
    release,
    start_service,
    stop_services,
)

# 1 MB line, binary noise with and without newlines, a line of invalid UTF-8, 20,000 short
# lines (more than a pipe holds: the child blocks unless it is read), then a last line.
NOISY_CHILD = r"""
import os, random, sys
out = sys.stdout.buffer
out.write(b"x" * 1_000_000 + b"\n")
rng = random.Random(16)
out.write(bytes(rng.randrange(256) for _ in range(200_000)))
out.write(b"\n\xff\xfe\xc3\x28 not utf-8\n")
for i in range(20_000):
    out.write(b"line %d\n" % i)
out.write(b"y" * 300_000)  # a long last line without a newline
out.flush()
os.write(1, b"\nlast\n")
"""


async def test_reader_survives_any_line_length_and_any_bytes() -> None:
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-P", "-c", NOISY_CHILD, stdout=asyncio.subprocess.PIPE
    )
    assert proc.stdout is not None
    lines: list[str] = []
    reader = asyncio.create_task(read_lines(proc.stdout, lines.append))
    assert await asyncio.wait_for(proc.wait(), 120) == 0  # never blocked on a full pipe
    await asyncio.wait_for(reader, 30)
    assert lines[0].startswith("x" * LINE_MAX) and "line of 1000000 bytes cut" in lines[0]
    assert all(len(line) <= LINE_MAX + 40 for line in lines)
    assert "\ufffd\ufffd\ufffd( not utf-8" in lines  # invalid UTF-8 replaced, the line kept
    numbered = [line for line in lines if line.startswith("line ")]
    assert numbered == [f"line {i}" for i in range(20_000)]
    assert lines[-2].startswith("y" * LINE_MAX) and "cut" in lines[-2]
    assert lines[-1] == "last"


async def test_a_stuck_service_is_reported_and_stopped(tmp_path: Path) -> None:
    config = private_config()
    env = env_for(config)
    reports: list[tuple[str, str]] = []
    with Bus.open(config) as bus:
        sp = await start_service("speech", env, options={"out_dir": str(tmp_path)})
        watch = HealthWatch(
            bus, [sp], lambda n, why: reports.append((n, why)), period=0.2, timeout=1.0,
            stuck_after=2,
        )  # fmt: skip
        try:
            await bus.wait_alive(bus.keys.alive("speech"), timeout=60)
            watch.start()
            loop = asyncio.get_running_loop()
            deadline = loop.time() + 60
            while watch.answered.get("speech", 0) < 3 and loop.time() < deadline:
                await asyncio.sleep(0.05)
            assert watch.answered.get("speech", 0) >= 3, watch.misses  # healthy: answers
            assert not reports and sp.running
            os.kill(sp.process.pid, signal.SIGSTOP)  # frozen: alive to the OS, answers nothing
            code = await asyncio.wait_for(sp.process.wait(), 90)
        finally:
            await watch.stop()
            await stop_services([sp])
    assert sp.stuck and code in (-signal.SIGTERM, -signal.SIGKILL, 0)
    assert reports and reports[0][0] == "speech" and "no health answer" in reports[0][1]


async def test_a_held_service_joins_the_bus_once_released_and_leaves_if_let_go(
    tmp_path: Path,
) -> None:
    """`beyond up` starts its processes held while it looks for another `up` on the bus: none
    of them may be seen there before it lets them in, and one let go (stdin closed) leaves
    without ever joining."""
    config = private_config()
    env = env_for(config)
    with Bus.open(config) as bus:
        seen: list[tuple[str, bool]] = []
        bus.watch_tokens(bus.keys.alive("*"), lambda key, present: seen.append((key, present)))
        options = {"out_dir": str(tmp_path)}
        let_go = await start_service("describer", env, held=True)
        sp = await start_service("speech", env, options=options, held=True)
        try:
            assert let_go.process.stdin is not None
            let_go.process.stdin.close()
            assert await asyncio.wait_for(let_go.process.wait(), 120) == 0
            with pytest.raises(TimeoutError):  # held: alive, but nothing of it on the bus
                await bus.wait_alive(bus.keys.alive("speech"), timeout=2.0)
            assert sp.running and sp.held
            release(sp)
            await bus.wait_alive(bus.keys.alive("speech"), timeout=60)
            assert not sp.held
        finally:
            codes = await stop_services([sp, let_go])
    assert codes == {"speech": 0, "describer": 0}
    assert {key.rsplit("/", 1)[-1] for key, _ in seen} == {"speech"}  # never the one let go
