"""The chaos run shared by test_chaos_a.py and test_chaos_b.py (issue 39): `beyond up`, playing
three-actions.mcap at rate 1, while a schedule drawn from a seed SIGKILLs its services (the same
one twice within a second, two at the same instant) or freezes one (SIGSTOP for 2-6 s, then
SIGCONT). Two files, so xdist's loadfile runs the seeds on two workers.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import random
import signal
from asyncio.subprocess import PIPE
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from busutil_net import env_for, private_config

from beyond_self.commands.analyse import _inputs, default_run
from beyond_self.services.launcher import BEYOND

RECORDING = Path(__file__).resolve().parent.parent / "recordings" / "three-actions.mcap"
SERVICES = ("ingest", "gestures", "objects", "reasoner", "describer", "speech")
SPAN_S = 18.0  # the recording plays for about 21 s at rate 1: every fault lands while it plays
AT_ONCE = 2  # runs side by side, each on a bus of its own: a run waits on real time most of it


@dataclass(frozen=True)
class Fault:
    at_s: float  # after the deployment started
    kind: str  # "kill" or "stop"
    victims: tuple[str, ...]
    frozen_s: float = 0.0

    def __str__(self) -> str:
        what = f"SIGSTOP {self.frozen_s:.1f} s" if self.kind == "stop" else "SIGKILL"
        return f"{self.at_s:5.2f} s {what} {'+'.join(self.victims)}"


def schedule(seed: int) -> list[Fault]:
    """Four faults: one service killed twice within a second (the kind turns with the seed, so
    eight seeds kill every kind), two killed at the same instant (ingest with the gesture
    streamer on even seeds), one frozen for 2-6 s, one more kill of any service."""
    rng = random.Random(seed)
    again = SERVICES[seed % len(SERVICES)]
    if seed % 2 == 0:
        pair: tuple[str, ...] = ("ingest", "gestures")
    else:
        pair = tuple(rng.sample(SERVICES, 2))
    first = rng.uniform(1.0, SPAN_S - 1.0)
    faults = [
        Fault(first, "kill", (again,)),
        Fault(first + rng.uniform(0.2, 0.9), "kill", (again,)),
        Fault(rng.uniform(1.0, SPAN_S), "kill", pair),
        Fault(rng.uniform(1.0, SPAN_S - 6.0), "stop", (rng.choice(SERVICES),), rng.uniform(2, 6)),
        Fault(rng.uniform(1.0, SPAN_S), "kill", (rng.choice(SERVICES),)),
    ]
    return sorted(faults, key=lambda f: f.at_s)


def offline_lines() -> list[str]:
    return default_run(_inputs(RECORDING, "right_hand", "torso")).lines


def gesture_lines(lines: list[str]) -> list[str]:
    return [line for line in lines if line.startswith("gesture ")]


def service_pid(up: int, name: str) -> int | None:
    """The process of service `name` that `beyond up` (pid `up`) runs now, from /proc."""
    for task in Path(f"/proc/{up}/task").glob("*"):
        with contextlib.suppress(OSError):
            for child in (task / "children").read_text().split():
                argv = Path(f"/proc/{child}/cmdline").read_bytes().decode().split("\0")
                if "service" in argv and argv[argv.index("service") + 1 :][:1] == [name]:
                    return int(child)
    return None


async def run(seed: int, out: Path, extra_env: dict[str, str] | None = None) -> dict[str, Any]:
    """`beyond up` under `schedule(seed)`: what it printed, said, and how it stopped."""
    faults = schedule(seed)
    env = {**env_for(private_config()), "BEYOND_LOG_FORMAT": "text", **(extra_env or {})}
    args = ["up", "--recording", str(RECORDING), "--rate", "1", "--no-live", "--out-dir", str(out)]
    events: list[str] = []
    stdout: list[str] = []
    stderr: list[str] = []
    loop = asyncio.get_running_loop()
    began = loop.time()
    up_now = asyncio.Event()

    def note(what: str) -> None:
        events.append(f"{loop.time() - began:5.2f} s {what}")

    up = await asyncio.create_subprocess_exec(
        *BEYOND, *args, env=env, cwd=out, stdout=PIPE, stderr=PIPE
    )

    async def read(stream: asyncio.StreamReader, into: list[str]) -> None:
        async for raw in stream:
            line = raw.decode(errors="replace").rstrip("\n")
            into.append(line)
            if line.startswith("pipeline up:"):
                up_now.set()
            elif line.startswith("[up] "):
                note(line)

    async def inflict(fault: Fault) -> None:
        await asyncio.sleep(max(0.0, fault.at_s - (loop.time() - began)))
        pids = {name: service_pid(up.pid, name) for name in fault.victims}
        if fault.kind == "kill":
            for p in pids.values():  # at the same instant: no await in between
                if p is not None:
                    with contextlib.suppress(ProcessLookupError):
                        os.kill(p, signal.SIGKILL)
            note("SIGKILL " + ", ".join(f"{n} (pid {p})" for n, p in pids.items()))
            return
        ((name, p),) = pids.items()
        if p is None:
            return
        with contextlib.suppress(ProcessLookupError):
            os.kill(p, signal.SIGSTOP)
        note(f"SIGSTOP {name} (pid {p})")
        try:
            await asyncio.sleep(fault.frozen_s)
        finally:
            with contextlib.suppress(ProcessLookupError):
                os.kill(p, signal.SIGCONT)
            note(f"SIGCONT {name} (pid {p})")

    assert up.stdout is not None and up.stderr is not None
    readers = [loop.create_task(read(up.stdout, stdout)), loop.create_task(read(up.stderr, stderr))]
    chaos: list[asyncio.Task[None]] = []
    try:
        await asyncio.wait_for(up_now.wait(), 120)
        began = loop.time()
        chaos = [loop.create_task(inflict(f)) for f in faults]
        await asyncio.wait_for(up.wait(), 120)
    except TimeoutError:
        events.append("failed: stalled")
    finally:
        for task in chaos:
            task.cancel()
        if up.returncode is None:
            up.kill()  # its services die with it (runtime.process.lifeline)
            await up.wait()
        await asyncio.gather(*readers, return_exceptions=True)
    said = out / "speech" / "speech.log"
    stopped = next((line for line in stderr if line.startswith("services stopped")), "")
    return {
        "schedule": [str(f) for f in faults],
        "events": events,
        "code": up.returncode,
        "codes": stopped,
        "lines": stdout,
        "spoken": [int(line.split("\t")[1]) for line in said.read_text().splitlines()]
        if said.exists()
        else [],
        "restarts": next((line for line in stderr if line.startswith("restarts:")), ""),
        "tail": stderr[-int((extra_env or {}).get("TAIL", 60)) :],
    }


def run_seeds(seeds: list[int], folder: Path) -> dict[int, dict[str, Any]]:
    """`run` of every seed, AT_ONCE of them at a time (as the event-time matrix runs two lanes):
    what a run prints and says does not depend on the load beside it, and it spends most of
    its time waiting on the recording's real time. Each in a folder of its own."""

    async def each() -> dict[int, dict[str, Any]]:
        gate = asyncio.Semaphore(AT_ONCE)

        async def one(seed: int) -> tuple[int, dict[str, Any]]:
            async with gate:
                out = folder / f"seed{seed}"
                out.mkdir()
                return seed, await run(seed, out)

        return dict(await asyncio.gather(*(one(seed) for seed in seeds)))

    return asyncio.run(each())


def explain(seed: int, run: dict[str, Any]) -> str:
    """The schedule of a seed and what happened, printed when it fails."""
    return "\n".join(
        [f"seed {seed}: schedule", *run["schedule"], "what happened:", *run["events"],
         run["restarts"], f"exit {run['code']}; {run['codes']}", "printed:",
         *run["lines"], f"spoken: {run['spoken']}", "its log's tail:", *run["tail"]]
    )  # fmt: skip


def check(seed: int, run: dict[str, Any], expected: list[str]) -> None:
    why = explain(seed, run)
    assert run["code"] == 0, why
    codes = run["codes"].partition("(exit codes: ")[2].rstrip(")").split(", ")
    assert codes and all(c.endswith(" 0") for c in codes), why
    assert gesture_lines(run["lines"]) == gesture_lines(expected), why
    said = sorted(run["spoken"])
    described = sorted(
        {int(line.split()[1].rstrip(":")) for line in expected if line.endswith('"')}
    )
    assert said == described, why


def seed_tests(seeds: list[int]) -> tuple[Any, Any, Any]:
    """A chaos file's fixtures and test for its `seeds`: `analyse`'s lines, every seed's run
    (chaos.AT_ONCE at a time) and one test per seed checking its own. The seeds are split
    over files so that xdist hands them to different workers."""

    @pytest.fixture(scope="module")
    def expected() -> list[str]:
        return offline_lines()

    @pytest.fixture(scope="module")
    def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[int, dict[str, Any]]:
        return run_seeds(seeds, tmp_path_factory.mktemp("chaos"))

    @pytest.mark.slow
    @pytest.mark.timeout(600)  # the first test's set-up runs every seed
    @pytest.mark.parametrize("seed", seeds)
    def test_chaos_changes_nothing(
        seed: int, expected: list[str], runs: dict[int, dict[str, Any]]
    ) -> None:
        check(seed, runs[seed], expected)

    return expected, runs, test_chaos_changes_nothing
