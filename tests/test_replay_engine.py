"""The one replay engine (runtime.recording.replay.Player) and the one rule for replay speed,
without a bus:
what both `beyond replay` and the ingest service rely on, checked where it is cheap to check."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import pytest
from busutil_net import skeleton_frames

import beyond_self.schemas as s
from beyond_self.core.errors import InputError
from beyond_self.runtime.recording.reader import read_recording
from beyond_self.runtime.recording.replay import Cue, Player, recorded_cues
from beyond_self.runtime.recording.replay_control import ReplayControl, check_rate, rate_option
from beyond_self.runtime.recording.writer import RecordingWriter

KEYS = s.Keys("r1")


def test_one_rule_for_rates() -> None:
    assert rate_option(0) is None and rate_option(0.0) is None  # as typed: 0 = as fast as possible
    assert rate_option(2) == 2.0 and check_rate(None) is None and check_rate(0.5) == 0.5
    for bad in (-1.0, float("nan"), float("inf"), 2e6):
        with pytest.raises(InputError, match=r"valid: a speed factor in .* or 0 for as fast"):
            rate_option(bad, "--rate")
    with pytest.raises(InputError, match=r"replay rate 0; valid: .* or None for as fast"):
        check_rate(0)  # in code, as fast as possible is None: 0 is a person's spelling only
    with pytest.raises(InputError, match="replay rate 0"):
        Player(rate=0)


def cues(stamps_ms: list[int]) -> list[Cue]:
    return [Cue(ms * 1_000_000, "k", ms * 1_000_000, None) for ms in stamps_ms]


async def test_cues_go_out_at_their_stamps_scaled_by_rate() -> None:
    loop = asyncio.get_running_loop()
    sent: list[tuple[int, float]] = []
    player = Player(rate=2.0)
    began = loop.time()
    n = await player.play(cues([1000, 1100, 1300]), lambda c: sent.append((c.at, loop.time())))
    assert n == 3 and [at for at, _ in sent] == [1_000_000_000, 1_100_000_000, 1_300_000_000]
    # due 0, 50 and 150 ms into the pass: never early (timing follows the stamps, not the loop)
    for (at, when), due in zip(sent, (0.0, 0.05, 0.15), strict=True):
        assert when - began >= due - 1e-3, (at, when - began, due)
    assert player.stats.span_s == pytest.approx(0.3) and player.stats.passes == 1

    fast = Player(rate=None)
    assert await fast.play(cues(list(range(0, 100_000, 1000))), lambda c: None) == 100
    assert fast.stats.speed > 10  # 100 s of stamps, no sleeping


async def test_pause_steps_one_cue_and_stop_ends_the_pass() -> None:
    control = ReplayControl(paused=True)
    stop = asyncio.Event()
    got: list[int] = []

    def send(cue: Cue) -> None:
        got.append(cue.at)
        if len(got) == 2:
            stop.set()

    player = Player(rate=None, control=control, stop=stop)
    task = asyncio.get_running_loop().create_task(player.play(cues([0, 10, 20, 30]), send))
    control.step()
    while not got:
        await asyncio.sleep(0)
    assert got == [0] and not task.done()  # held after one step
    control.toggle()  # play on
    assert await asyncio.wait_for(task, 10) == 2 and player.stats.messages == 2


def test_recorded_cues_decode_once_rename_and_skip(tmp_path: Path) -> None:
    path = tmp_path / "r.mcap"
    frames = skeleton_frames(3)
    with RecordingWriter(path) as writer:
        for f in frames:
            writer.write(KEYS.skeleton, f)
        writer.write_raw("beyond/r1/other", b"raw", "text/plain", frames[-1].header.stamp + 1)
    out = list(recorded_cues(read_recording(path), lambda k: k.replace("r1", "r2")))
    assert [c.key for c in out] == ["beyond/r2/sensors/skeleton"] * 3 + ["beyond/r2/other"]
    assert [c.stamp for c in out[:3]] == [f.header.stamp for f in frames]
    assert [c.ours() for c in out[:3]] == frames and out[0].at == frames[0].header.stamp
    with pytest.raises(InputError, match="not a beyond message"):
        out[3].ours()  # sent as recorded by `beyond replay`, refused by the ingest
    skipped = recorded_cues(read_recording(path), lambda k: None if "other" in k else k)
    assert len(list(skipped)) == 3


def test_a_looped_source_is_restamped_pass_after_pass(tmp_path: Path) -> None:
    """Each pass later than the one before by the recording's span and a second: a consumer
    that refuses stamps going back takes every pass (issue 21); a camera frame's timestamp
    moves with its header. A restarted source starts with the pass its consumers are in."""
    from beyond_self.runtime.recording.replay import LOOP_GAP_S, looped
    from beyond_self.schemas import CameraFrame

    path = tmp_path / "r.mcap"
    frames = skeleton_frames(3)
    with RecordingWriter(path) as writer:
        for f in frames:
            writer.write(KEYS.skeleton, f)
        writer.write(KEYS.camera, CameraFrame.build(frames[-1].header, 2, 2, bytes(12)))
    first, last = frames[0].header.stamp, frames[-1].header.stamp
    period = last - first + round(LOOP_GAP_S * 1e9)
    passes = 0

    def one() -> Any:
        nonlocal passes
        passes += 1
        return recorded_cues(read_recording(path)) if passes <= 3 else iter(())

    cues = list(looped(one, loop=True, span=(first, last)))
    assert len(cues) == 12
    stamps = [c.stamp for c in cues]
    assert stamps == sorted(stamps) and len(set(stamps[::4])) == 3  # forward, pass after pass
    assert [c.stamp - cues[i % 4].stamp for i, c in enumerate(cues)] == [
        k * period for k in range(3) for _ in range(4)
    ]
    camera = cues[-1].ours()
    assert isinstance(camera, CameraFrame) and camera.timestamp.to_ns() == camera.header.stamp
    passes = 0
    resumed = list(looped(one, loop=True, span=(first, last), resume_at=stamps[5]))
    assert resumed[0].stamp == stamps[4]  # the second pass, from its start
