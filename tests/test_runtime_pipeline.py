"""Acceptance: two services as separate processes over Zenoh on loopback; a recording replayed
into them twice (once in-process, once with `beyond replay`) gives byte-identical outputs."""

from __future__ import annotations

import asyncio
import signal
import subprocess
import sys
from pathlib import Path

from busutil_net import EXAMPLES, env_for, private_config, skeleton_frames

import beyond_self.schemas as s
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.bus.subscription import RawSubscription
from beyond_self.runtime.recording.replay import replay
from beyond_self.runtime.recording.writer import RecordingWriter
from beyond_self.services.launcher import BEYOND

N = 150
THRESHOLD = 1.6  # the segmenter's, on doubled coordinates


def expected_segments(frames: list[s.SkeletonFrame]) -> list[tuple[str, int]]:
    """(event, stamp) computed straight from the synthetic input, not from the services."""
    events, active = [], False
    for f in frames:
        y = 2 * f.joints["hand_right"].position[1]
        if not active and y > THRESHOLD:
            events.append(("start", f.header.stamp))
            active = True
        elif active and y <= THRESHOLD:
            events.append(("end", f.header.stamp))
            active = False
    return events


async def collect(sub: RawSubscription, want: dict[str, int], timeout: float = 20) -> dict:
    got: dict[str, list[bytes]] = {key: [] for key in want}
    while any(len(got[k]) < n for k, n in want.items()):
        sample = await sub.recv(timeout=timeout)
        got[sample.key].append(sample.payload)
    return got


async def health_once_all_handled(
    bus: Bus, keys: s.Keys, timeout: float = 30
) -> dict[str, s.ServiceHealth]:
    """Both services' health once each has taken all N frames in: the last segment event can
    come out before the segmenter has read the quiet frames after it."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while True:
        replies = await bus.query(keys.health(), s.ServiceHealth, timeout=5, every=True)
        health = {r.message.service: r.message for r in replies}
        handled = [h.messages_in for h in health.values()]
        if (len(handled) == 2 and min(handled) >= N) or loop.time() > deadline:
            return health
        await asyncio.sleep(0.05)


async def test_two_services_replay_twice_identical(tmp_path: Path) -> None:
    config = private_config()
    frames = skeleton_frames(N)
    segments = expected_segments(frames)
    assert len(segments) >= 4
    recording = tmp_path / "input.mcap"
    keys = s.Keys(config.robot)
    with RecordingWriter(recording) as writer:
        for f in frames:
            writer.write(keys.skeleton, f)

    env = env_for(config, BEYOND_CLOCK="recording")
    doubled_key = f"{keys.root}/example/doubled"
    want = {doubled_key: N, keys.gesture_segment: len(segments)}
    runs = []
    with Bus.open(config) as bus:
        sub = bus.subscribe_raw([doubled_key, keys.gesture_segment])
        # The services keep state (the segmenter's open segment and ids), so each run starts
        # them fresh, as a deployment would be restarted for a replay.
        for use_cli in (False, True):
            procs = [
                subprocess.Popen(
                    [sys.executable, str(EXAMPLES / f"{name}.py")],
                    env=env,
                    stderr=subprocess.PIPE,
                    text=True,
                )
                for name in ("doubler", "segmenter")
            ]
            try:
                await bus.wait_alive(keys.alive(), count=2, timeout=30)
                probe = bus.publisher(keys.skeleton, s.SkeletonFrame)
                await probe.wait_matching(timeout=10)
                probe.put_bytes(b"not a skeleton")  # garbage first: counted, skipped
                probe.close()
                if use_cli:
                    cli = await asyncio.create_subprocess_exec(
                        *BEYOND,
                        "replay",
                        str(recording),
                        "--afap",
                        "--wait-for",
                        keys.alive("segmenter"),
                        env=env,
                        stderr=asyncio.subprocess.PIPE,
                    )
                    runs.append(await collect(sub, want))
                    _, cli_err = await asyncio.wait_for(cli.communicate(), 30)
                    assert cli.returncode == 0, cli_err.decode()
                    assert f"replayed {N} messages" in cli_err.decode()
                else:
                    await replay(bus, recording, rate=None)
                    runs.append(await collect(sub, want))
                health = await health_once_all_handled(bus, keys)
                assert health["doubler"].malformed == 1
                assert health["doubler"].messages_in == N
                assert health["doubler"].messages_out == N
                assert health["doubler"].dropped == 0
                assert health["segmenter"].messages_in == N
                # recording time on replay: health carries the last input's stamp
                assert health["doubler"].header.stamp == frames[-1].header.stamp
            finally:
                for proc in procs:
                    if proc.poll() is None:
                        proc.send_signal(signal.SIGTERM)
                codes = [proc.wait(timeout=15) for proc in procs]
            assert codes == [0, 0]
            await bus.wait_gone(keys.alive(), timeout=10)
        assert len(sub._inbox) == 0  # nothing beyond what was expected

    first, second = runs
    assert first == second  # byte-identical, in the same order
    doubled = [s.decode(p, s.SkeletonFrame) for p in first[doubled_key]]
    for out, f in zip(doubled, frames, strict=True):
        assert out.header.stamp == f.header.stamp
        assert out.header.correlation == f.header.correlation
        assert out.joints["hand_right"].position == tuple(
            2 * v for v in f.joints["hand_right"].position
        )
    events = [s.decode(p, s.GestureSegment) for p in first[keys.gesture_segment]]
    assert [(e.event, e.header.stamp) for e in events] == segments
