"""The chaos run shared by test_chaos_a.py and test_chaos_b.py (issue 39): the pipeline `beyond
up` starts, playing three-actions.mcap at rate 1, while a schedule drawn from a seed SIGKILLs
services (the same one twice within a second, two at the same instant) or freezes one
(SIGSTOP for 2-6 s, then SIGCONT). Two files, so xdist's loadfile runs the seeds on two workers.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import random
import signal
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from busutil_net import private_config

from beyond_self.commands.analyse import _inputs, default_run
from beyond_self.monitor import PipelineMonitor
from beyond_self.services.deployment import Deployment

RECORDING = Path(__file__).resolve().parent.parent / "recordings" / "three-actions.mcap"
SERVICES = ("ingest", "gestures", "objects", "reasoner", "describer", "speech")
SPAN_S = 18.0  # the recording plays for about 21 s at rate 1: every fault lands while it plays


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


async def run(seed: int, out: Path, extra_env: dict[str, str] | None = None) -> dict[str, Any]:
    """One deployment under `schedule(seed)`: what it printed, said, and how it stopped."""
    faults = schedule(seed)
    extra_env = extra_env or {}
    lines: list[str] = []
    events: list[str] = []
    loop = asyncio.get_running_loop()
    began = loop.time()

    def note(what: str) -> None:
        events.append(f"{loop.time() - began:5.2f} s {what}")

    pipeline = Deployment(
        private_config(),
        ["gestures", "objects", "reasoner", "describer", "speech", "ingest"],
        options={
            "ingest": {"recording": str(RECORDING), "rate": 1.0},
            "speech": {"out_dir": str(out)},
        },
        watcher="monitor",
        clock="recording",
        env={"BEYOND_LOG_FORMAT": "text", **extra_env},
        on_restart=lambda name, what: note(f"{name}: {what}"),
    )
    bus = await pipeline.open()
    monitor = PipelineMonitor.of(pipeline, bus, lines.append)
    monitor.start()

    def pid(name: str) -> int | None:
        proc = next(p for p in pipeline.processes if p.name == name)
        return proc.process.pid if proc.running else None

    async def inflict(fault: Fault) -> None:
        await asyncio.sleep(max(0.0, fault.at_s - (loop.time() - began)))
        pids = {name: pid(name) for name in fault.victims}
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

    log = out / "speech.log"
    chaos: list[asyncio.Task[None]] = []
    try:
        await pipeline.start()
        began = loop.time()
        chaos = [loop.create_task(inflict(f)) for f in faults]
        while not (monitor.done() and all(t.done() for t in chaos)):
            assert loop.time() - began < 100, "stalled"
            assert not pipeline.exited(), pipeline.exited()
            monitor.changed.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(monitor.changed.wait(), 0.25)
    except AssertionError as exc:
        events.append(f"failed: {exc}")
    finally:
        monitor.stop()
        for task in chaos:
            task.cancel()
        codes = await pipeline.stop()
    said = log.read_text().splitlines() if log.exists() else []
    return {
        "schedule": [str(f) for f in faults],
        "events": events,
        "codes": codes,
        "lines": lines,
        "spoken": [int(line.split("\t")[1]) for line in said],
        "restarts": {n: r.count for n, r in pipeline.restarts.items()},
        "tails": {
            p.name: list(p.lines)[-int(extra_env.get("TAIL", 30)) :] for p in pipeline.processes
        },
    }


def explain(seed: int, run: dict[str, Any]) -> str:
    """The schedule of a seed and what happened, printed when it fails."""
    return "\n".join(
        [f"seed {seed}: schedule", *run["schedule"], "what happened:", *run["events"],
         f"restarts: {run['restarts']}", f"exit codes: {run['codes']}", "printed:",
         *run["lines"], f"spoken: {run['spoken']}"]
        + [f"{name}: {line}" for name, tail in run["tails"].items() for line in tail]
    )  # fmt: skip


def check(seed: int, run: dict[str, Any], expected: list[str]) -> None:
    why = explain(seed, run)
    assert set(run["codes"].values()) == {0}, why
    assert gesture_lines(run["lines"]) == gesture_lines(expected), why
    said = sorted(run["spoken"])
    described = sorted(
        {int(line.split()[1].rstrip(":")) for line in expected if line.endswith('"')}
    )
    assert said == described, why
