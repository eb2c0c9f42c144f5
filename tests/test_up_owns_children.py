"""`beyond up` owns its services (issue 39): SIGKILLed mid-gesture, it leaves none behind, and the
same command again goes on with the run (both runs' lines together are `analyse`'s, each sentence
said once); a second `up` for a robot whose services are on the bus says so in one line and
exits 2."""

from __future__ import annotations

import asyncio
import os
import signal
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from busutil_net import REPO, env_for, private_config, run_beyond
from test_lifeline import gone, wait_gone

import beyond_self.schemas as s
from beyond_self.runtime.bus.delivery import EVENTS
from beyond_self.runtime.bus.session import Bus
from beyond_self.services.launcher import BEYOND
from beyond_self.services.registry import PROFILES

RECORDING = REPO / "recordings" / "three-actions.mcap"


def descendants(pid: int) -> list[int]:
    """Every process below `pid` (children, theirs, ...), from /proc."""
    found: list[int] = []
    todo = [pid]
    while todo:
        parent = todo.pop()
        for task in Path(f"/proc/{parent}/task").glob("*"):
            try:
                kids = [int(k) for k in (task / "children").read_text().split()]
            except FileNotFoundError:
                continue
            found += kids
            todo += kids
    return found


def gesture_lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.startswith("gesture ")]


@pytest.mark.slow
async def test_up_killed_mid_gesture_leaves_no_service_and_goes_on_when_run_again(
    tmp_path: Path, show: Callable[[str], None], test_outputs: Path
) -> None:
    config = private_config()
    env = {**env_for(config), "BEYOND_LOG_FORMAT": "text"}
    args = ["up", "--recording", str(RECORDING), "--rate", "1", "--no-live", "--timeout", "90"]
    first_out = tmp_path / "up.out"
    with (
        Bus.open(config) as bus,
        (tmp_path / "up.err").open("w") as err,
        first_out.open("w") as out,
    ):
        segments = bus.subscribe(bus.keys.gesture_segment, s.GestureSegment, EVENTS)
        up = await asyncio.create_subprocess_exec(
            *BEYOND, *args, env=env, cwd=tmp_path, stdout=out, stderr=err
        )
        children: list[int] = []
        try:
            services = PROFILES["all"]
            await bus.wait_alive(bus.keys.alive("*"), count=len(services) + 1, timeout=90)
            code, out, said = await run_beyond(args, env=env, cwd=tmp_path, timeout=60)
            assert code == 2, said
            assert out == ""
            assert len(said.splitlines()) == 1, said
            assert said.startswith(f"beyond up: error: robot {config.robot!r} already has ingest")
            seen = (await segments.recv(timeout=60)).message
            while (seen.segment_id, seen.event) != (2, "start"):  # mid-gesture: the second's
                seen = (await segments.recv(timeout=60)).message
            for _ in range(600):  # and the first gesture told (under load it may come later)
                if any('"' in line for line in gesture_lines(first_out.read_text())):
                    break
                await asyncio.sleep(0.1)
            children = descendants(up.pid)
            assert len(children) >= len(services)  # and the object segmenter's describer
            up.send_signal(signal.SIGKILL)
            killed = time.monotonic()
            await up.wait()
            left = wait_gone(children, 2.0)
            assert left == [], [Path(f"/proc/{p}/cmdline").read_bytes() for p in left]
            took = time.monotonic() - killed
            show(f"{len(children)} processes of up gone {took * 1000:.0f} ms after its SIGKILL")
        finally:
            if up.returncode is None:
                up.kill()
                await up.wait()
            for pid in children:
                if not gone(pid):
                    os.kill(pid, signal.SIGKILL)
    # the same command again, from the same folder: it goes on from what the first run left
    code, again, said = await run_beyond(args, env=env, cwd=tmp_path, timeout=150)
    assert code == 0, said[-3000:]
    assert "[up] going on with the run begun" in said, said[-3000:]
    code, analysed, why = await run_beyond(
        ["analyse", str(RECORDING)], env=env, cwd=tmp_path, timeout=120
    )
    assert code == 0, why
    before = gesture_lines(first_out.read_text())
    assert before, "the first run told nothing before its kill"
    assert before + gesture_lines(again) == gesture_lines(analysed)
    sentences = [line.split(': "', 1)[1][:-1] for line in gesture_lines(analysed) if ': "' in line]
    spoken = (test_outputs / "speech" / "speech.log").read_text().splitlines()
    assert [line.split("\t")[-1] for line in spoken] == sentences  # each said once, in order
    assert "3 of 3 gesture(s) described" in again
    show(f"killed after {len(before)} line(s); the second run printed {len(gesture_lines(again))}")
