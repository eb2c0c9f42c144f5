"""The example service of runtime/README.md, run as written: the docs cannot drift from the API.

The code block between the `example-service` markers is written to a file and run twice: in
this process on a private bus (the description it publishes for an ended gesture, its health
counting a malformed event), and as a program (`python timer.py`, stopped with SIGTERM, exit 0).
"""

from __future__ import annotations

import asyncio
import importlib.util
import os
import re
import signal
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import msgspec
from busutil_net import env_for, private_config

from beyond_self.runtime.bus.delivery import EVENTS
from beyond_self.runtime.bus.session import Bus
from beyond_self.schemas import Description, GestureSegment, Header

README = Path(__file__).resolve().parents[1] / "runtime" / "README.md"


def example_source() -> str:
    text = README.read_text(encoding="utf-8")
    found = re.search(
        r"<!-- example-service -->\n```python\n(.*?)```\n<!-- /example-service -->", text, re.S
    )
    assert found, "runtime/README.md lost its example-service block"
    return found.group(1)


def load_example(tmp_path: Path) -> ModuleType:
    path = tmp_path / "timer.py"
    path.write_text(example_source(), encoding="utf-8")
    spec = importlib.util.spec_from_file_location("readme_timer", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def segment(event: str, segment_id: int, start_s: float, end_s: float | None) -> GestureSegment:
    start = round(start_s * 1e9)
    end = None if end_s is None else round(end_s * 1e9)
    stamp = end if end is not None else start
    header = Header(version=2, source="gestures", seq=segment_id, stamp=stamp, correlation="x")
    return GestureSegment(
        header=header, event=event, segment_id=segment_id, frame=1, start_stamp=start,  # type: ignore[arg-type]
        end_stamp=end,
    )  # fmt: skip


def test_the_example_is_about_thirty_lines() -> None:
    lines = example_source().strip().splitlines()
    assert 25 <= len(lines) <= 40, len(lines)


async def test_the_example_describes_each_ended_gesture_and_counts_bad_input(
    tmp_path: Path,
) -> None:
    timer_cls = load_example(tmp_path).GestureTimer
    config = private_config()
    timer = timer_cls(config=config, health_period=0.2)
    task = asyncio.create_task(timer.run(install_signals=False))
    try:
        with Bus.open(config) as bus:
            keys = bus.keys
            described = bus.subscribe(keys.description, Description, EVENTS)
            await bus.wait_alive(keys.alive("timer"), timeout=30)
            events = bus.publisher(keys.gesture_segment, GestureSegment, EVENTS)
            events.put(segment("start", 7, 10.0, None))
            events.put_bytes(b"\x93not an event")
            events.put(segment("end", 7, 10.0, 11.5))
            got = (await described.recv(timeout=30)).message
            assert got.segment_id == 7
            assert [s.text for s in got.sentences] == ["it lasted 1.5 s"]
            assert got.header.stamp == round(11.5e9)  # derived: the end event's stamp
            loop = asyncio.get_running_loop()
            deadline = loop.time() + 30
            while timer.health_report().malformed < 1 and loop.time() < deadline:
                await asyncio.sleep(0.05)
            health = timer.health_report()
            assert (health.malformed, health.errors, health.messages_out) == (1, 0, 1)
    finally:
        timer.stop()
        await asyncio.wait_for(task, 30)


async def test_the_example_runs_as_a_program_and_stops_on_sigterm(tmp_path: Path) -> None:
    load_example(tmp_path)  # writes timer.py
    config = private_config()
    env = env_for(config)
    proc = subprocess.Popen(
        [sys.executable, str(tmp_path / "timer.py")],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        cwd=tmp_path,
    )
    try:
        with Bus.open(config) as bus:
            await bus.wait_alive(bus.keys.alive("timer"), timeout=60)
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL)
    assert proc.returncode == 0, out.decode(errors="replace")
    logged = [msgspec.json.decode(line) for line in out.splitlines() if line.startswith(b"{")]
    assert any(e.get("event") == "stopped" for e in logged), out.decode(errors="replace")
