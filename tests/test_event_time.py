"""Event time (issue 12): a replay's outputs depend on the recording, never on timing.

The matrix: every shipped recording as fast as possible, the shortest also at 4x, 1x and 0.5x,
the demo recording at 4x, two runs at a time, each on a bus of its own; three busy-looping
processes beside the pipelines the whole time; the services (ingest included: it waits for its
consumers) started in a shuffled order with random delays; and one run where the object
segmenter is killed with SIGKILL while a gesture is under way and started again (the player
waits for it, it gets the frames back from the camera cache and does not publish again what its
predecessor had). Every run must print the gesture lines `beyond analyse` prints offline for the
same recording, and every derived stream must carry the same messages, byte for byte, in every
run of a recording.
"""

from __future__ import annotations

import asyncio
import contextlib
import random
from collections.abc import Callable
from pathlib import Path

import pytest
from busutil_net import private_config

import beyond_self.schemas as s
from beyond_self.cognition.bn import learn_network, synthetic_dataset
from beyond_self.cognition.episodes.offline import analyse_stream
from beyond_self.cognition.gestures.default_models import default_models
from beyond_self.cognition.vision.clusters import ClusterModel
from beyond_self.commands.analyse import _inputs
from beyond_self.monitor import PipelineMonitor
from beyond_self.runtime.delivery import FRAMES
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
    run = analyse_stream(
        _inputs(RECORDINGS / name, "right_hand", "torso"),
        gesture_models=default_models(),
        clusters=ClusterModel.load(),
        network=learn_network(synthetic_dataset()),
    )
    return run.lines


async def run_pipeline(
    name: str, rate: float, seed: int, kill_during: int | None = None
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
    monitor = PipelineMonitor(bus, lines.append)
    monitor.start()

    async def capture(stream: str) -> None:
        cls = s.STREAMS[stream][1]
        async for received in bus.subscribe(keys.stream(stream), cls, FRAMES):
            captured[stream].append(s.encode(received.message))

    tasks = [asyncio.get_running_loop().create_task(capture(k)) for k in DERIVED]
    order = [*CONSUMERS, "ingest"]
    rng.shuffle(order)  # any start order: the source waits for its consumers itself
    killed = []
    try:
        for service in order:
            await asyncio.sleep(rng.uniform(0.0, 0.8))
            await pipeline.launch(service)
        deadline = asyncio.get_running_loop().time() + 240
        while not monitor.done():
            assert asyncio.get_running_loop().time() < deadline, (name, rate, lines)
            g = monitor.report.gestures.get(kill_during or 0)
            if g is not None and g.started is not None and not killed:
                victim = next(p for p in pipeline.processes if p.name == "objects")
                victim.process.kill()  # SIGKILL: no clean-up, mid-gesture
                await victim.process.wait()
                killed.append(victim)
                await bus.wait_gone(keys.alive("objects"), timeout=30)
                await pipeline.launch("objects")
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
    assert len(killed) == (kill_during is not None), "the gesture to kill during never started"
    return lines, captured


MATRIX: list[tuple[str, float, int | None]] = [
    *[(name, 0.0, None) for name in SHIPPED],  # as fast as possible
    ("touch-box.mcap", 4.0, None),
    ("touch-box.mcap", 1.0, None),
    ("touch-box.mcap", 0.5, None),
    ("tap-ball-grasp-box.mcap", 4.0, None),
    ("tap-ball-grasp-box.mcap", 4.0, 2),  # the object segmenter killed during gesture 2
]


LANES = 2  # runs at once, each on a bus of its own: twice the pipelines competing for the CPU


@pytest.mark.slow
@pytest.mark.timeout(900)
async def test_replays_equal_the_offline_analysis_at_any_rate_under_load(
    busy_machine: None, show: Callable[[str], None]
) -> None:
    expected = {name: offline_lines(name) for name in SHIPPED}
    results: dict[int, tuple[list[str], dict[str, list[bytes]]]] = {}

    async def lane(k: int) -> None:
        for seed in range(k, len(MATRIX), LANES):
            name, rate, kill_during = MATRIX[seed]
            results[seed] = await run_pipeline(name, rate, seed, kill_during)
            assert results[seed][0] == expected[name], (name, rate)

    async with asyncio.TaskGroup() as lanes:  # a failure in one lane stops the other's pipeline
        for k in range(LANES):
            lanes.create_task(lane(k))
    first: dict[str, dict[str, list[bytes]]] = {}
    table = []
    for seed, (name, rate, kill_during) in enumerate(MATRIX):
        lines, captured = results[seed]
        reference = first.setdefault(name, captured)
        same = all(captured[k] == reference[k] for k in DERIVED)
        kill = f"objects SIGKILLed in gesture {kill_during}" if kill_during else ""
        count = sum(map(len, captured.values()))
        table.append((name, rate or "max", kill, len(lines), count, same))
        assert same, (name, rate, {k: (len(captured[k]), len(reference[k])) for k in DERIVED})
    assert all(expected[n] for n in SHIPPED)  # every recording has described gestures
    show("\n".join(" ".join(["event-time matrix:", *map(str, row)]) for row in table))
