"""A stray message cannot derail a run (issue 42): during `beyond up` of a recording, the
README's `beyond pub` example (a skeleton frame with no hand, stamped by the wall clock) and the
same frame with a whole skeleton are refused as another source's, counted in the gesture
streamer's health, and change nothing: the gesture lines equal `beyond analyse`'s, exit 0."""

from __future__ import annotations

import asyncio
import contextlib
import json
from pathlib import Path

import msgspec
import pytest
from busutil_net import env_for, private_config, run_beyond

import beyond_self.schemas as s
from beyond_self.commands.analyse import _inputs, default_run
from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.delivery import RELIABLE, STATUS
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.clock import Clock
from beyond_self.runtime.service import Service
from beyond_self.services.launcher import BEYOND

RECORDING = Path(__file__).resolve().parent.parent / "recordings" / "three-actions.mcap"
README_FRAME = '{"frame": 1, "joints": {"head": {"position": [0, 0.4, 2]}}}'
WHOLE_FRAME = json.dumps(
    {
        "frame": 1,
        "joints": {
            "head": {"position": [0, 0.4, 2]},
            "torso": {"position": [0, 0, 2]},
            "right_hand": {"position": [0.3, 0.1, 1.8]},
        },
    }
)


class HandTracker(Service):
    """A paced skeleton consumer that refuses a frame without a right hand, as the gesture
    streamer does."""

    name = "hands"

    def __init__(self, **base: object) -> None:
        super().__init__(**base)  # type: ignore[arg-type]
        self.handled: list[int] = []
        self.last = asyncio.Event()

    async def setup(self) -> None:
        self.subscribe(self.bus.keys.skeleton, s.SkeletonFrame, self.on_frame, paced=True)

    def on_frame(self, frame: s.SkeletonFrame) -> None:
        if "right_hand" not in frame.joints:
            raise InputError(f"skeleton frame {frame.frame} has no joint 'right_hand'")
        self.handled.append(frame.header.stamp)
        if frame.frame == 99:
            self.last.set()


def _frame(source: str, stamp: int, number: int, *, hand: bool = True) -> s.SkeletonFrame:
    joints = {"head": s.Joint(position=(0.0, 0.4, 2.0))}
    if hand:
        joints["right_hand"] = s.Joint(position=(0.3, 0.1, 1.8))
    header = s.Header(version=s.SkeletonFrame.VERSION, source=source, seq=number, stamp=stamp)
    return s.SkeletonFrame(header=header, frame=number, joints=joints)


async def test_a_foreign_or_refused_frame_moves_no_time_of_the_owner() -> None:
    """In one process: the first source accepted owns the key; a bad frame before it claims
    nothing; another source's frames, whole or not and however late their stamps, are counted
    as foreign and move neither the stream's time nor the service's clock; the owner's bad
    frame is refused and its next frames are handled, none stale."""
    year = 10**18
    with Bus.open(private_config()) as bus:
        service = HandTracker(bus=bus, clock=Clock("recording"), health_period=60)
        task = asyncio.get_running_loop().create_task(service.run(install_signals=False))
        await asyncio.wait_for(service.started.wait(), 20)
        pub = bus.publisher(bus.keys.skeleton, s.SkeletonFrame, RELIABLE)
        await pub.wait_matching(timeout=20)
        for frame in (
            _frame("beyond-pub", 2 * year, 1, hand=False),  # refused before any owner
            _frame("sim", 100, 1),
            _frame("sim", 200, 2),
            _frame("beyond-pub", 2 * year, 3, hand=False),  # the README's frame
            _frame("beyond-pub", 2 * year, 4),  # the same, whole
            _frame("sim", 300, 5, hand=False),  # the owner's own bad frame
            _frame("sim", 400, 99),
        ):
            pub.put(frame)
        await asyncio.wait_for(service.last.wait(), 20)
        health = service.health_report()
        clock = service.clock.now_ns()
        owner = service._times.owner(bus.keys.skeleton)
        service.stop()
        await asyncio.wait_for(task, 10)
    assert service.handled == [100, 200, 400]
    assert (health.foreign, health.refused, health.stale) == (2, 2, 0)
    assert health.errors == 2  # the refusals are bad input, logged and counted
    assert owner == "sim" and clock == 400


@pytest.mark.slow
async def test_stray_skeleton_frames_during_up_change_nothing(tmp_path: Path) -> None:
    config = private_config()
    env = {**env_for(config), "BEYOND_LOG_FORMAT": "text"}
    expected = default_run(_inputs(RECORDING, "right_hand", "torso")).lines
    skeleton = f"beyond/{config.robot}/sensors/skeleton"
    seen: list[s.ServiceHealth] = []
    with Bus.open(config) as bus:

        async def watch_health() -> None:
            sub = bus.subscribe(bus.keys.health("gestures"), s.ServiceHealth, STATUS)
            async for received in sub:
                seen.append(received.message)

        watching = asyncio.get_running_loop().create_task(watch_health())
        up = await asyncio.create_subprocess_exec(
            *BEYOND, "up", "--recording", str(RECORDING), "--rate", "1", "--no-live",
            "--timeout", "90", env=env, cwd=tmp_path,
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
        )  # fmt: skip
        assert up.stdout is not None and up.stderr is not None
        printed: list[str] = []
        sent = False
        try:
            async with asyncio.timeout(150):
                while line := (await up.stdout.readline()).decode():
                    printed.append(line.rstrip("\n"))
                    if line.startswith("gesture 1") and not sent:
                        sent = True
                        # mid-run, while gesture 1 is under way: both frames, as the README
                        # shows them, from `beyond pub` (source "beyond-pub", wall-clock stamp)
                        for frame in (README_FRAME, WHOLE_FRAME):
                            code, out, err = await run_beyond(
                                ["pub", skeleton, "SkeletonFrame", frame],
                                env=env, cwd=tmp_path, timeout=60,
                            )  # fmt: skip
                            assert code == 0, out + err
                errors = (await up.stderr.read()).decode()
                code = await up.wait()
        finally:
            if up.returncode is None:
                up.kill()
                await up.wait()
            watching.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await watching
    gestures = [line for line in printed if line.startswith("gesture ")]
    assert code == 0, "\n".join(printed) + errors[-3000:]
    assert gestures == expected, "\n".join(printed) + errors[-3000:]
    assert max((h.foreign for h in seen), default=0) == 2, (repr(seen[-1]), errors[-3000:])
    assert max((h.stale for h in seen), default=0) == 0
    assert "belongs to" in errors  # the one line that says why they were refused


@pytest.mark.slow
async def test_a_recording_that_begins_with_frames_without_a_hand_plays_to_its_end(
    tmp_path: Path,
) -> None:
    """Refused frames move no time, but the player waiting on the gesture streamer still sees
    them read: thirty hand-less frames at the start (no owner yet) do not stall `up --rate 0`,
    and the rest of the recording is described."""
    from beyond_self.runtime.recording.reader import inspect_recording, read_recording
    from beyond_self.runtime.recording.writer import RecordingWriter

    bad = tmp_path / "no-hand-at-first.mcap"
    with RecordingWriter(bad, metadata=inspect_recording(RECORDING).metadata["beyond"]) as out:
        for item in read_recording(RECORDING):
            message = item.message()
            if isinstance(message, s.SkeletonFrame) and message.frame <= 30:
                joints = {k: v for k, v in message.joints.items() if k != "right_hand"}
                message = msgspec.structs.replace(message, joints=joints)
            out.write(item.key, message)
    env = {**env_for(private_config()), "BEYOND_LOG_FORMAT": "text"}
    up = ["up", "--recording", str(bad), "--rate", "0", "--no-live", "--timeout", "50"]
    try:
        code, printed, errors = await run_beyond(up, env=env, cwd=tmp_path, timeout=60)
    except TimeoutError:
        pytest.fail("beyond up stalled on a recording that begins with refused frames")
    assert code == 0, printed + errors[-3000:]
    said = [line for line in printed.splitlines() if line.startswith("gesture ")]
    assert said and said[-1].endswith('"the robot touched the ball but the ball is still"'), printed
    assert "refused=30" in errors  # the gesture streamer's own count, as it stopped
