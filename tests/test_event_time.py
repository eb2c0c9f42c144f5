"""Event time (issue 12): a replay's outputs depend on the recording, never on timing; and
crash-only services (issue 21): none of it changes when a service is killed and restarted.

The matrix: every shipped recording as fast as possible, the shortest also at 4x and 1x (real time),
the demo recording at 4x, two runs at a time, each on a bus of its own; three busy-looping
processes beside the pipelines the whole time; the services (ingest included: it waits for its
consumers) started in a shuffled order with random delays. Every run must print the gesture
lines `beyond analyse` prints offline for the same recording, and every derived stream must
carry the same messages, byte for byte, in every run of a recording.

The kill columns: one deployment per rate (x1 and as fast as possible) plays the shortest
recording in a loop (`loop: true`, each pass restamped: gesture n is pass n), and kills with
SIGKILL, each in turn, the ingest, the gesture streamer, the object segmenter, the reasoner, the
describer and the speech service, each as soon as gesture n (its turn) is seen starting; the
deployment restarts them itself, as `beyond up` does. Then: every process stops cleanly, the
lines equal `beyond analyse`'s over the same looped stream, and every gesture's description is
published once and said once (the speech log).
"""

from __future__ import annotations

import asyncio
import contextlib
import random
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from busutil_net import private_config

import beyond_self.schemas as s
from beyond_self.cognition.episodes.report import GestureLines
from beyond_self.commands.analyse import _inputs, default_run, looped_inputs
from beyond_self.monitor import PipelineMonitor
from beyond_self.runtime.bus.delivery import FRAMES
from beyond_self.services.deployment import Deployment

RECORDINGS = Path(__file__).resolve().parent.parent / "recordings"
SHIPPED = sorted(p.name for p in RECORDINGS.glob("*.mcap"))
DERIVED = (
    "gesture_segment",
    "gesture_posterior",
    "objects",
    "gesture_object",
    "effects",
    "affordance",
    "words",
    "description",
)
CONSUMERS = ["gestures", "objects", "reasoner", "describer"]


def offline_lines(name: str) -> list[str]:
    return default_run(_inputs(RECORDINGS / name, "right_hand", "torso")).lines


async def run_pipeline(
    name: str, rate: float, seed: int
) -> tuple[list[str], dict[str, list[bytes]]]:
    rng = random.Random(seed)
    lines: list[str] = []
    captured: dict[str, list[bytes]] = {k: [] for k in DERIVED}
    pipeline = Deployment(
        private_config(),
        [*CONSUMERS, "ingest"],
        options={"ingest": {"recording": str(RECORDINGS / name), "rate": rate}},
        watcher="monitor",
        clock="recording",
        env={"BEYOND_LOG_FORMAT": "text"},
    )
    bus = await pipeline.open()
    keys = bus.keys
    monitor = PipelineMonitor.of(pipeline, bus, lines.append)
    monitor.start()

    async def capture(stream: str) -> None:
        cls = s.STREAMS[stream][1]
        async for received in bus.subscribe(keys.stream(stream), cls, FRAMES):
            captured[stream].append(s.encode(received.message))

    tasks = [asyncio.get_running_loop().create_task(capture(k)) for k in DERIVED]
    order = [*CONSUMERS, "ingest"]
    rng.shuffle(order)  # any start order: the source waits for its consumers itself
    try:
        for service in order:
            await asyncio.sleep(rng.uniform(0.0, 0.8))
            await pipeline.launch(service)
        deadline = asyncio.get_running_loop().time() + 240
        while not monitor.done():
            assert asyncio.get_running_loop().time() < deadline, (name, rate, lines)
            dead = pipeline.exited()
            assert not dead, (dead, [p.lines[-10:] for p in pipeline.processes])
            monitor.changed.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(monitor.changed.wait(), 0.5)
    finally:
        monitor.stop()
        for task in tasks:
            task.cancel()
        codes = await pipeline.stop()
    assert set(codes.values()) == {0}, (codes, [p.lines[-10:] for p in pipeline.processes])
    assert not pipeline.restarts, "nothing died"
    return lines, captured


KILLED = ("ingest", "gestures", "objects", "reasoner", "describer", "speech")  # gesture 1, 2, ...
KILL_RECORDING = "touch-box.mcap"  # the shortest: one gesture a pass


def looped_lines(name: str, passes: int) -> list[str]:
    """`beyond analyse` over the recording looped as the ingest loops it."""
    return default_run(looped_inputs(RECORDINGS / name, passes)).lines


def of_gestures(lines: list[str], last: int) -> list[str]:
    return [line for line in lines if int(line.split(":")[0].split()[1]) <= last]


async def kill_each_in_turn(rate: float, out: Path) -> dict[str, Any]:
    """One looped deployment; each service of KILLED killed as its gesture starts."""
    lines: list[str] = []
    described: list[int] = []
    events: list[str] = []  # what happened when: shown when an assertion fails
    loop = asyncio.get_running_loop()
    began = loop.time()

    def note(what: str) -> None:
        events.append(f"{loop.time() - began:.1f} s {what}")

    pipeline = Deployment(
        private_config(),
        [*CONSUMERS, "speech", "ingest"],
        options={
            "ingest": {"recording": str(RECORDINGS / KILL_RECORDING), "rate": rate, "loop": True},
            "speech": {"out_dir": str(out)},
        },
        watcher="monitor",
        clock="recording",
        env={"BEYOND_LOG_FORMAT": "text"},
        on_restart=lambda name, what: note(f"{name}: {what}"),
    )
    bus = await pipeline.open()
    monitor = PipelineMonitor.of(pipeline, bus, lines.append)
    monitor.start()

    async def capture() -> None:
        async for received in bus.subscribe(bus.keys.description, s.Description, FRAMES):
            described.append(received.message.segment_id)

    capturing = loop.create_task(capture())
    last = len(KILLED) + 1  # one more gesture after the last restart
    killed: list[str] = []
    log = out / "speech.log"

    def finished() -> bool:  # the last gesture printed, published and said
        said = log.exists() and log.read_text().count("\n") >= last
        return (
            monitor.report.gestures.get(last, GestureLines()).printed
            and said
            and (last in described)
        )

    try:
        await pipeline.start()
        while not finished():
            assert loop.time() - began < 300, "\n".join(
                [f"rate {rate}: stalled; what happened:", *events, "what it printed:", *lines]
                + [f"{p.name}: {line}" for p in pipeline.processes for line in list(p.lines)[-8:]]
            )
            turn = len(killed)
            g = monitor.report.gestures.get(turn + 1)
            if turn < len(KILLED) and g is not None and g.started is not None:
                victim = next(p for p in pipeline.processes if p.name == KILLED[turn])
                assert victim.running, (victim.name, events)
                victim.process.kill()  # SIGKILL, mid-gesture: no clean-up
                killed.append(victim.name)
                note(f"gesture {turn + 1} started: {victim.name} killed")
            assert not pipeline.exited(), (pipeline.exited(), events)
            monitor.changed.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(monitor.changed.wait(), 0.25)
    finally:
        monitor.stop()
        capturing.cancel()
        codes = await pipeline.stop()
    return {
        "codes": codes,
        "lines": lines,
        "described": described,
        "spoken": [int(line.split("\t")[1]) for line in log.read_text().splitlines()],
        "killed": killed,
        "events": events,
        "restarts": {n: r.count for n, r in pipeline.restarts.items()},
        "seconds": round(loop.time() - began, 1),
        "unclean": {p.name: list(p.lines)[-6:] for p in pipeline.processes if codes[p.name]},
    }


@pytest.mark.slow
@pytest.mark.timeout(600)
async def test_each_service_killed_mid_gesture_and_restarted_changes_nothing(
    tmp_path: Path, show: Callable[[str], None]
) -> None:
    """Before the matrix (its busy processes stay up until the module ends)."""
    last = len(KILLED) + 1
    rates = (1.0, 0.0)
    offline = asyncio.to_thread(looped_lines, KILL_RECORDING, last)  # beside the pipelines
    *runs, lines = await asyncio.gather(
        *(kill_each_in_turn(r, tmp_path / f"rate{r}") for r in rates), offline
    )
    expected = of_gestures(lines, last)
    assert [line for line in expected if line.endswith('"')], "gestures are described"
    table = []
    gestures = list(range(1, last + 1))
    for rate, run in zip(rates, runs, strict=True):
        why = (rate, run["events"])
        assert run["killed"] == list(KILLED), why
        assert run["restarts"] == {name: 1 for name in KILLED}, why
        assert set(run["codes"].values()) == {0}, (*why, run["unclean"])  # all stop cleanly
        assert of_gestures(run["lines"], last) == expected, (*why, run["lines"])
        # every gesture described, and said exactly once. A SIGKILL that lands between a
        # service's output and its ledger entry (no transaction spans both) lets its successor
        # send that output again, with the same identity, which every consumer skips: the lines
        # above and the speech log show each once. At most one repeat per kill.
        described = [g for g in run["described"] if g <= last]
        repeats = len(described) - len(set(described))
        assert sorted(set(described)) == gestures and repeats <= len(KILLED), (*why, run)
        assert sorted(g for g in run["spoken"] if g <= last) == gestures, (*why, run)
        table.append(
            f"rate {rate or 'max'}: {run['seconds']} s, restarts {run['restarts']}, "
            f"descriptions sent again {repeats}"
        )
    show("kill columns (each service SIGKILLed mid-gesture, restarted):\n" + "\n".join(table))


MATRIX: list[tuple[str, float]] = [
    *[(name, 0.0) for name in SHIPPED],  # as fast as possible
    ("touch-box.mcap", 4.0),
    ("touch-box.mcap", 1.0),
    ("tap-ball-grasp-box.mcap", 4.0),
]


LANES = 2  # runs at once, each on a bus of its own: twice the pipelines competing for the CPU


@pytest.fixture(scope="module")
def expected() -> dict[str, list[str]]:
    """`beyond analyse`'s lines of every shipped recording, made before the busy loop starts
    (the matrix asks for it first): 2.6 CPU-s, twice as long on the core beside the spinner."""
    return {name: offline_lines(name) for name in SHIPPED}


@pytest.mark.slow
@pytest.mark.timeout(900)
async def test_replays_equal_the_offline_analysis_at_any_rate_under_load(
    expected: dict[str, list[str]], busy_machine: str, show: Callable[[str], None]
) -> None:
    results: dict[int, tuple[list[str], dict[str, list[bytes]]]] = {}

    async def lane(k: int) -> None:
        for seed in range(k, len(MATRIX), LANES):
            name, rate = MATRIX[seed]
            results[seed] = await run_pipeline(name, rate, seed)
            assert results[seed][0] == expected[name], (name, rate)

    async with asyncio.TaskGroup() as lanes:  # a failure in one lane stops the other's pipeline
        for k in range(LANES):
            lanes.create_task(lane(k))
    first: dict[str, dict[str, list[bytes]]] = {}
    table = []
    for seed, (name, rate) in enumerate(MATRIX):
        lines, captured = results[seed]
        reference = first.setdefault(name, captured)
        same = all(captured[k] == reference[k] for k in DERIVED)
        count = sum(map(len, captured.values()))
        table.append((name, rate or "max", len(lines), count, same))
        assert same, (name, rate, {k: (len(captured[k]), len(reference[k])) for k in DERIVED})
    assert all(expected[n] for n in SHIPPED)  # every recording has described gestures
    title = f"event-time matrix ({busy_machine}):"
    show("\n".join(" ".join([title, *map(str, row)]) for row in table))
