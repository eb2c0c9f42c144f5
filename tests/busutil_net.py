"""Helpers for bus tests: a private Zenoh group per test, synthetic skeleton frames, and a
loaded machine (also used by bench/pipeline.py).

Every test gets its own rendezvous port (probed free on 127.0.0.1) and its own robot name, so
tests never meet each other or other people's processes; multicast scouting is off by default.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import socket
import subprocess
import sys
import uuid
from collections.abc import Iterator
from pathlib import Path

from beyond_self.runtime.bus.config import BusConfig
from beyond_self.runtime.bus.session import Bus
from beyond_self.schemas import Header, Joint, Keys, Ledger, Message, ServiceHealth, SkeletonFrame

REPO = Path(__file__).resolve().parent.parent
EXAMPLES = Path(__file__).resolve().parent / "runtime_examples"


def free_port() -> int:
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextlib.contextmanager
def busy_loops(n: int, cpu: int | None = None) -> Iterator[None]:
    """`n` processes spinning on the CPU (`while True: pass`) while the block runs: on a 2-core
    machine, three leave the pipeline a fraction of a core per service. `cpu`: the spinners,
    and every process this thread starts meanwhile, confined to that core."""
    before = os.sched_getaffinity(0)
    if cpu is not None:
        os.sched_setaffinity(0, {cpu})  # this thread: inherited by what it starts
    spin = [sys.executable, "-P", "-c", "while True: pass"]
    try:
        spinners = [subprocess.Popen(spin) for _ in range(n)]
        try:
            yield
        finally:
            for p in spinners:
                p.kill()
                p.wait()
    finally:
        os.sched_setaffinity(0, before)


def private_config() -> BusConfig:
    return BusConfig(robot=f"t{uuid.uuid4().hex[:10]}", port=free_port())


def health_report(service: str, seq: int = 0) -> ServiceHealth:
    """A service's health as it reports it while idle (what a watch of health hears)."""
    header = Header(version=ServiceHealth.VERSION, source=service, seq=seq, stamp=seq + 1)
    return ServiceHealth(
        header=header,
        service=service,
        uptime_s=0.0,
        messages_in=1,
        messages_out=2,
        dropped=0,
        malformed=0,
        errors=0,
    )


def env_for(config: BusConfig, **extra: str) -> dict[str, str]:
    """Environment that makes a child process join the same private group."""
    env = dict(os.environ)
    for name in ("BEYOND_ZENOH_CONFIG", "BEYOND_ZENOH_CONNECT", "BEYOND_ZENOH_LISTEN"):
        env.pop(name, None)
    env.update(
        BEYOND_ROBOT=config.robot,
        BEYOND_ZENOH_PORT=str(config.port),
        BEYOND_ZENOH_MODE="peer",
        BEYOND_LOG_FORMAT="json",
        PYTHONPATH=str(REPO),
        **extra,
    )
    return env


async def run_beyond(
    args: list[str], *, env: dict[str, str], cwd: Path, timeout: float
) -> tuple[int, str, str]:
    """Exit status, stdout and stderr of `beyond ARGS` in its own process, without blocking the
    event loop (a test's own subscriptions keep receiving meanwhile)."""
    from beyond_self.services.launcher import BEYOND

    proc = await asyncio.create_subprocess_exec(
        *BEYOND,
        *args,
        env=env,
        cwd=cwd,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )
    try:
        out, err = await asyncio.wait_for(proc.communicate(), timeout)
    finally:
        if proc.returncode is None:  # timed out (TimeoutError goes on): leave no process behind
            proc.kill()
            await proc.wait()
    assert proc.returncode is not None
    return proc.returncode, out.decode(), err.decode()


def python() -> str:
    return sys.executable


JOINTS = ("head", "torso", "hand_left", "hand_right", "elbow_right", "shoulder_right")


def skeleton_frames(n: int, *, start_ns: int = 1_700_000_000_000_000_000, hz: float = 30.0):
    """A deterministic right-hand reach: `n` SkeletonFrames at `hz`."""
    period = int(1e9 / hz)
    frames = []
    for i in range(n):
        t = i / hz
        joints = {}
        for j, name in enumerate(JOINTS):
            x = 0.1 * j + (0.3 * math.sin(2 * math.pi * 0.5 * t) if name == "hand_right" else 0)
            y = (
                0.5
                + 0.05 * j
                + (0.2 * (1 - math.cos(2 * math.pi * 0.5 * t)) if name == "hand_right" else 0.0)
            )
            joints[name] = Joint(position=(round(x, 6), round(y, 6), 2.0), confidence=1.0)
        frames.append(
            SkeletonFrame(
                header=Header(
                    version=1,
                    source="synthetic",
                    seq=i,
                    stamp=start_ns + i * period,
                    correlation=f"synthetic/{i}",
                ),
                frame=i,
                joints=joints,
            )
        )
    return frames


def skeleton_recording(path: Path, actions: list[str], seed: int, robot: str = "robot") -> None:
    """A recording of synthetic gestures, skeleton frames only (no camera): the services then
    describe the gestures without measured effects."""
    from beyond_self.cognition.gestures import synthesize_continuous
    from beyond_self.cognition.scene import SCENE_GESTURES
    from beyond_self.runtime.recording.writer import RecordingWriter

    # gestures on a table, as in the shipped recordings (no slow taps in the air)
    stream = synthesize_continuous(actions, seed=seed, config=SCENE_GESTURES)
    key = Keys(robot).skeleton
    t0 = 1_546_300_800_000_000_000
    with RecordingWriter(path) as writer:
        for i in range(stream.n_frames):
            joints = {
                n: Joint(position=(float(p[i, 0]), float(p[i, 1]), float(p[i, 2])))
                for n, p in stream.joints.items()
            }
            header = Header(version=1, source="sim", seq=i, stamp=t0 + i * 33_333_333)
            writer.write(key, SkeletonFrame(header=header, frame=i + 1, joints=joints))


def serve_cut_predecessor(bus: Bus, first: int) -> None:
    """Answer ledger queries on `bus` as a run whose gesture streamer told its checkpoint at
    `first` after gesture 1, and whose reasoner has gesture 1 whole and gesture 2's start only:
    a restarted streamer whose skeleton cache starts after `first` cannot rebuild gesture 2."""
    key = bus.keys.gesture_segment
    kept = [
        Ledger(
            header=Ledger.original_header("gestures", 9, first), service="gestures",
            resume={"gestures": 1, "events": 3}, resume_stamps={"stamp": first},
        ),
        Ledger(
            header=Ledger.original_header("reasoner", 9, first), service="reasoner",
            handled={key: {"start": [(1, 0, 0), (2, 0, 0)], "end": [(1, 0, 0)]}},
        ),
    ]  # fmt: skip

    async def answer(_key: str, _request: None) -> list[tuple[str, Message]]:
        return [(bus.keys.ledger(m.service), m) for m in kept]

    bus.queryable(bus.keys.ledger(), None, answer)
