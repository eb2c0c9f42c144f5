"""A sharded workstation (issue 51): each stage of a fleet runs as two processes on one machine,
each serving the robots a stable hash of their names gives it (runtime/shard.py), and a shard
SIGKILLed while a burst of gestures is in flight is restarted by its supervisor, its robots'
runs resuming from their ledgers: every robot prints the lines `beyond analyse` prints for its
own recording and says each sentence once.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import threading
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import pytest
from busutil_net import private_config
from test_fleet import Echo, wait_until

from beyond_self.cli import main
from beyond_self.commands.analyse import _inputs, default_run
from beyond_self.core.errors import InputError
from beyond_self.monitor import PipelineMonitor
from beyond_self.runtime.bus.config import BusConfig
from beyond_self.runtime.bus.delivery import FRAMES
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.fleet import LEAVE_ENV, Fleet
from beyond_self.runtime.shard import Shard, parse_shard, shard_count, shard_of
from beyond_self.schemas import GestureSegment, Header, Joint, Keys, SkeletonFrame
from beyond_self.schemas.keys import for_robots, split_key
from beyond_self.services.deployment import Deployment
from beyond_self.services.launcher import ServiceProcess

STAGES = ["gestures", "reasoner", "describer"]  # skeleton only: no object segmenter
ROBOTS = {  # robot -> its gestures; lab-1 is shard 0's, lab-4 and lab-5 shard 1's
    "lab-1": ["tap", "grasp"],
    "lab-4": ["grasp", "touch"],
    "lab-5": ["touch", "tap"],
}
KILLED_STAGE, KILLED = "reasoner", 1  # the shard killed mid-burst: shard 1 of the reasoner
GO = "go"  # the starting gun: every robot's source waits for it, so all play at once
RATE = 3  # the recordings replay three times faster than they were made


def test_robots_keep_their_shard_and_spread_over_the_shards() -> None:
    """The assignment is the robot's name's alone (no Python `hash()`, salted per process): the
    values below are BLAKE2b's, which anyone can compute; and many robots fill every shard
    about evenly (64 over 4: 16 each expected, a binomial's spread about 3.5)."""
    assert [shard_of(r, 2) for r in ROBOTS] == [0, 1, 1]
    assert shard_of("lab-1", 1) == 0
    for count in (2, 3, 4, 7):
        names = [f"lab-{k}" for k in range(16 * count)]
        per = Counter(shard_of(n, count) for n in names)
        assert sorted(per) == list(range(count)) and all(8 <= n <= 24 for n in per.values()), per
        shards = [Shard(k, count) for k in range(count)]
        assert all(sum(s.serves(n) for s in shards) == 1 for n in names)  # one shard each
    assert parse_shard("1/2") == Shard(1, 2) and str(Shard(1, 2)) == "1/2"
    assert Shard(0, 2).host("ws-1") == "ws-1.shard0"
    assert shard_count("auto") == len(os.sched_getaffinity(0))
    for bad in ("2/2", "-1/2", "x", "1/0"):
        with pytest.raises(InputError, match="valid: K/N"):
            parse_shard(bad)
    for bad in ("0", "x", "-1", "1.5", "257"):
        with pytest.raises(InputError, match=r"valid: 1 to 256 processes per stage, or auto"):
            shard_count(bad)


@pytest.mark.parametrize("value", ["0", "x"])
def test_up_refuses_a_bad_number_of_shards(value: str, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["up", "--profile", "fleet-workstation", "--robots", "lab-*", "--shards", value])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert f"argument --shards: {value!r} is not a number of shards; valid: 1 to 256" in err[0]


def test_shards_need_a_fleet_and_hosts_apart_from_its_robots() -> None:
    config = BusConfig(robot="ws", robots="lab-*")
    side = Deployment(config, STAGES, options={"reasoner": {"objects": False}}, shards=2)
    assert list(side.units) == [f"{n}.shard{k}" for n in STAGES for k in (0, 1)]
    assert side.units["reasoner.shard1"].command == [
        "service", "reasoner", "--robot", "ws.shard1", "--shard", "1/2"
    ]  # fmt: skip
    assert list(Deployment(config, STAGES, shards=1).units) == STAGES  # as it always was
    with pytest.raises(InputError, match="shards share out a fleet's robots; give --robots"):
        Deployment(BusConfig(robot="ws"), STAGES, shards=2)
    with pytest.raises(InputError, match="not on a secure bus yet"):
        Deployment(config.with_(secure="keys", mode="client"), STAGES, shards=2)
    with pytest.raises(InputError, match=r"sharded, not ingest \(one robot's own\)"):
        Deployment(config, ["ingest", "gestures"], shards=2)
    with pytest.raises(InputError, match=r"shard host 'ws\.shard0' is one of the robots 'ws\.\*'"):
        Deployment(BusConfig(robot="ws", robots="ws.*"), STAGES, shards=2)


async def test_each_shard_serves_its_own_robots_and_none_of_a_dead_siblings() -> None:
    """Shards 0 and 1 of one service (in this process, each on its own session as its own
    host): each serves the robots its shard gives it; shard 1 gone (its session closed, tokens
    and all), shard 0 does not wait to take its robots over; shard 1 back (as its supervisor
    would start it), it serves them again."""
    config = private_config()
    loop = asyncio.get_running_loop()

    def shard(k: int, bus: Bus) -> tuple[Fleet, asyncio.Task[None]]:
        ws = config.with_(robot=Shard(k, 2).host("ws"), robots="lab-*")
        fleet = Fleet(Echo, ws, bus=bus, takeover_after_s=0.2, shard=Shard(k, 2))
        return fleet, loop.create_task(fleet.run(install_signals=False))

    with Bus.open(config) as robots, Bus.open(config) as bus0:
        bus1 = Bus.open(config)
        (zero, task0), (one, task1) = shard(0, bus0), shard(1, bus1)
        present: list[Callable[[], None]] = []
        try:
            views = [robots.for_robot(name) for name in ROBOTS]
            present = [v.declare_token(v.keys.alive("ingest")) for v in views]
            await wait_until("each shard its own", lambda: (zero.robots, one.robots) == (
                ["lab-1"], ["lab-4", "lab-5"]))  # fmt: skip
            hosts = await robots.live_tokens(Keys("lab-4").server("echo"))
            assert hosts == ["beyond/lab-4/alive/echo/ws.shard1"]
            task1.cancel()  # shard 1 dies
            bus1.close()
            await wait_until("shard 0 saw it go", lambda: not zero.served_by.get("lab-4"))
            # no takeover under way, nor ever to come: shard 0 is not waiting on them
            assert zero.robots == ["lab-1"] and not zero._takeover and not zero._unserved_since
            bus1 = Bus.open(config)
            one, task1 = shard(1, bus1)
            await wait_until("shard 1 back", lambda: one.robots == ["lab-4", "lab-5"])
            assert zero.robots == ["lab-1"] and zero.takeovers == 0
        finally:
            for undeclare in present:
                undeclare()
            for fleet in (zero, one):
                fleet.stop()
            await asyncio.gather(task0, task1, return_exceptions=True)
            bus1.close()


def burst_recordings(folder: Path) -> dict[str, Path]:
    """Each robot's recording: its own gestures, its person at rest for as long before them as
    makes its last gesture end on the same frame as every other robot's (a burst)."""
    from beyond_self.cognition.gestures import synthesize_continuous
    from beyond_self.cognition.scene import SCENE_GESTURES
    from beyond_self.runtime.recording.writer import RecordingWriter

    streams = {
        r: synthesize_continuous(a, seed=3, config=SCENE_GESTURES) for r, a in ROBOTS.items()
    }

    def write(path: Path, robot: str, rest: int) -> None:
        stream = streams[robot]
        with RecordingWriter(path) as writer:
            for i in range(rest + stream.n_frames):
                at = max(0, i - rest)
                joints = {
                    n: Joint(position=(float(p[at, 0]), float(p[at, 1]), float(p[at, 2])))
                    for n, p in stream.joints.items()
                }
                header = Header(version=1, source="sim", seq=i, stamp=10**18 + i * 33_333_333)
                writer.write(
                    Keys().skeleton, SkeletonFrame(header=header, frame=i + 1, joints=joints)
                )

    ends = {}
    for robot in ROBOTS:
        write(folder / f"{robot}-raw.mcap", robot, 0)
        ends[robot] = last_end(folder / f"{robot}-raw.mcap")
    paths = {robot: folder / f"{robot}.mcap" for robot in ROBOTS}
    for robot, path in paths.items():
        write(path, robot, max(ends.values()) - ends[robot])
    return paths


def analysed(path: Path) -> list[str]:
    return default_run(_inputs(path, "right_hand", "torso")).lines


def last_end(path: Path) -> int:
    ended = [line for line in analysed(path) if " ended at frame " in line]
    return int(ended[-1].rsplit(" ", 1)[1])


def descendants(pids: list[int]) -> list[int]:
    """`pids` and every process under them still there."""
    found: list[int] = []
    for pid in pids:
        with contextlib.suppress(OSError):
            children = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
            found += [pid, *descendants([int(c) for c in children])]
    return found


@pytest.mark.slow  # about 15 s: twelve processes start
@pytest.mark.timeout(120)
async def test_a_shard_killed_mid_burst_repeats_nothing_and_loses_nothing(
    tmp_path: Path,
) -> None:
    """Two shards of each stage on one workstation; three robots whose last gestures end on one
    frame, their sources started together. Once one of shard 1's robots has said its first
    gesture, the reasoner of shard 1 is paused (so none of its robots can have its last gesture
    described before the kill); once every robot's last gesture has ended (the burst in flight),
    it is SIGKILLed. Its supervisor starts it again; each robot's lines are `beyond analyse`'s
    of its own recording, each of its sentences said once, and nothing is left running."""
    recordings = burst_recordings(tmp_path)
    expected = {robot: analysed(path) for robot, path in recordings.items()}
    assert len({last_end(path) for path in recordings.values()}) == 1  # a burst
    base = private_config()
    env = {"BEYOND_LOG_FORMAT": "text", LEAVE_ENV: "60"}
    workstation = Deployment(
        base.with_(robot="ws", robots="lab-*"), STAGES, options={"reasoner": {"objects": False}},
        clock="recording", env=env, shards=2,
    )  # fmt: skip
    robots = {
        robot: Deployment(
            base.with_(robot=robot), ["ingest", "speech"],
            options={"ingest": {"recording": str(path), "rate": RATE},
                     "speech": {"out_dir": str(tmp_path / robot)}},
            wait_for=[*STAGES, GO], watcher="monitor", clock="recording", env=env,
        )
        for robot, path in recordings.items()
    }  # fmt: skip
    sides = [workstation, *robots.values()]
    lines: dict[str, list[str]] = {robot: [] for robot in robots}
    monitors: dict[str, PipelineMonitor] = {}
    seen: dict[tuple[str, str], set[int]] = {}  # (robot, segment event) -> its gestures
    victim: ServiceProcess | None = None
    mine = [r for r in robots if shard_of(r, 2) == KILLED]
    guns: list[Callable[[], None]] = []
    give_up = threading.Event()
    bus = await workstation.open()
    segments = bus.subscribe(for_robots("lab-$*", Keys().gesture_segment), GestureSegment, FRAMES)

    async def watch_segments() -> None:
        async for got in segments:
            robot = split_key(got.key)[0]  # type: ignore[index]
            seen.setdefault((robot, got.message.event), set()).add(got.message.segment_id)

    def robots_at(event: str, gesture: int) -> list[str]:
        return [r for r in robots if gesture in seen.get((r, event), ())]

    watching = asyncio.get_running_loop().create_task(watch_segments())
    try:
        for robot, side in robots.items():
            monitors[robot] = PipelineMonitor.of(side, await side.open(), lines[robot].append)
            monitors[robot].start()
        await workstation.start()
        await asyncio.gather(*(side.start() for side in robots.values()))
        started = [sp for side in sides for sp in side.processes]
        victim = next(sp for sp in started if sp.name == f"{KILLED_STAGE}.shard{KILLED}")
        for robot in robots:  # each robot's runs, on its shard
            for stage in STAGES:
                await bus.wait_alive(Keys(robot).alive(stage), timeout=60)
        pauser = threading.Thread(
            target=pause_once_said, args=(victim, tmp_path, mine, 1, give_up), daemon=True
        )
        pauser.start()
        guns = [bus.declare_token(Keys(robot).alive(GO)) for robot in robots]
        began = time.monotonic()
        await asyncio.to_thread(pauser.join, 60)
        assert not pauser.is_alive(), "waiting for a first gesture of the killed shard's said"
        await wait_until("every last gesture ended", lambda: len(robots_at("end", 2)) == 3, 60)
        said_at_kill = {r: said(tmp_path, r) for r in robots}
        victim.process.kill()
        killed_at = time.monotonic()
        await wait_until("every robot done", lambda: all(m.done() for m in monitors.values()), 60)
        started += [sp for sp in workstation.processes if sp not in started]
        assert not [n for side in sides for n in side.exited()]
    finally:
        give_up.set()
        if victim is not None:  # paused, it would not hear SIGTERM
            with contextlib.suppress(ProcessLookupError):
                victim.process.send_signal(signal.SIGCONT)
        for monitor in monitors.values():
            monitor.stop()
        watching.cancel()
        for undeclare in guns:
            undeclare()
        codes = [await side.stop() for side in reversed(sides)]
    took = time.monotonic() - began
    print(f"{len(robots)} robots, {KILLED_STAGE} shard {KILLED} killed {killed_at - began:.1f} s "
          f"in, with {said_at_kill} said; all said {took:.1f} s in")  # fmt: skip
    assert all(set(c.values()) <= {0, -signal.SIGTERM} for c in codes), codes
    restarts = {n: r.count for n, r in workstation.restarts.items() if r.count}
    assert restarts == {victim.name: 1}, restarts
    # mid-burst: every robot's last gesture had ended, and the killed shard's had not been said
    assert mine and all(2 not in said_at_kill[r] for r in mine), said_at_kill
    for robot in robots:
        assert lines[robot] == expected[robot], (robot, lines[robot], expected[robot])
        assert said(tmp_path, robot) == [1, 2], said_lines(tmp_path, robot)  # each once
    assert descendants([sp.process.pid for sp in started]) == []  # nothing left behind


def pause_once_said(
    victim: ServiceProcess, folder: Path, robots: list[str], gesture: int, give_up: threading.Event
) -> None:
    """SIGSTOP `victim` as soon as one of `robots` has said `gesture`, polled from a thread of
    its own: the test's loop, busy with its monitors, would see it late, and the pipeline could
    say the next gesture first. Returns unpaused once `give_up` is set."""
    while not give_up.wait(0.005):
        if any(gesture in said(folder, r) for r in robots):
            victim.process.send_signal(signal.SIGSTOP)
            return


def said_lines(folder: Path, robot: str) -> list[str]:
    log = folder / robot / "speech.log"
    return log.read_text().splitlines() if log.exists() else []


def said(folder: Path, robot: str) -> list[int]:
    """The gestures robot `robot`'s speech has said, in the order said."""
    return [int(line.split("\t")[1]) for line in said_lines(folder, robot)]
