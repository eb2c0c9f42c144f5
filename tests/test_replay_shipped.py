"""Issue 5's acceptance on a shipped recording: the gesture streamer and the affordance reasoner
run as separate processes over Zenoh on loopback; `recordings/touch-box.mcap` is replayed into
them twice (fresh services each time, as a replayed deployment is restarted) and every output
stream must be byte-identical, in the same order (the replay paced by its consumers)."""

from __future__ import annotations

import asyncio
from pathlib import Path

from busutil_net import private_config

import beyond_self.schemas as s
from beyond_self.runtime.bus.config import BusConfig
from beyond_self.runtime.bus.delivery import FRAMES
from beyond_self.runtime.recording.replay import replay
from beyond_self.services.deployment import Deployment

RECORDING = Path(__file__).resolve().parent.parent / "recordings" / "touch-box.mcap"


async def _run_once(config: BusConfig, keys: s.Keys) -> list[tuple[str, bytes]]:
    outputs: list[tuple[str, bytes]] = []
    pipeline = Deployment(
        config,
        ["gestures", "reasoner"],
        options={"reasoner": {"objects": False}},
        clock="recording",
        env={"BEYOND_LOG_FORMAT": "text"},
    )
    bus = await pipeline.open()
    # derived streams are published with a cache and never block: read them as services
    # do, recovering what a congested moment dropped
    streams = {
        keys.gesture_segment: s.GestureSegment,
        keys.gesture_posterior: s.ActionPosterior,
        keys.affordance: s.AffordancePrediction,
        keys.words: s.WordProbabilities,
    }
    arrived: asyncio.Queue[tuple[str, bytes]] = asyncio.Queue()

    async def capture(key: str, cls: type[s.Message]) -> None:
        async for received in bus.subscribe(key, cls, FRAMES):
            arrived.put_nowait((key, s.encode(received.message)))

    tasks = [asyncio.get_running_loop().create_task(capture(k, c)) for k, c in streams.items()]
    try:
        await pipeline.start()
        recorded = s.Keys("robot").skeleton  # the recording's own robot name
        stats = await replay(
            bus,
            RECORDING,
            rate=None,
            topics=[recorded],
            robot=keys.robot,
            pace_for=["gestures", "reasoner"],
        )
        assert stats.messages > 100 and not stats.damaged
        # until every stream's last message of the one gesture is in: its words, its end
        # event, its final posterior and final prediction (they travel on different keys,
        # so the words may well come before the end event)
        last = {
            keys.words: lambda m: True,
            keys.gesture_segment: lambda m: m.event == "end",
            keys.gesture_posterior: lambda m: m.final,
            keys.affordance: lambda m: m.final,
        }
        done: set[str] = set()
        while done != set(last):
            key, payload = await asyncio.wait_for(arrived.get(), 30)
            outputs.append((key, payload))
            if last[key](s.decode(payload, streams[key])):
                done.add(key)
    finally:
        for task in tasks:
            task.cancel()
        codes = await pipeline.stop()
    # clean exits
    assert set(codes.values()) == {0}, (codes, [p.lines[-8:] for p in pipeline.processes])
    return outputs


async def test_shipped_recording_replays_to_identical_bytes() -> None:
    config = private_config()
    keys = s.Keys(config.robot)
    first = await _run_once(config, keys)
    second = await _run_once(config, keys)
    # each stream byte-identical and in the same order (streams interleave as they will)
    for key in {k for k, _ in first}:
        assert [p for k, p in first if k == key] == [p for k, p in second if k == key], key
    kinds = {key for key, _ in first}
    assert kinds == {keys.gesture_segment, keys.gesture_posterior, keys.affordance, keys.words}
    words = s.decode(next(p for k, p in first if k == keys.words), s.WordProbabilities)
    assert words.final and words.segment_id == 1
    belief = words.action_belief
    assert max(belief, key=belief.__getitem__) == "touch"  # the recording shows a touch
