"""A fleet on one workstation (issue 24): one process per service serves every robot a pattern
matches, a run per robot created when the robot's source appears and dropped when it leaves
(runtime/fleet.py), and every robot gets the lines `beyond analyse` prints for its recording.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from busutil_net import private_config

from beyond_self.commands.analyse import _inputs, default_run
from beyond_self.core.errors import InputError
from beyond_self.monitor import PipelineMonitor
from beyond_self.runtime.bus.config import BusConfig
from beyond_self.runtime.bus.delivery import EVENTS
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.fleet import LEAVE_ENV, Fleet
from beyond_self.runtime.recording.recorder import record
from beyond_self.runtime.service import Service
from beyond_self.schemas import (
    Description,
    Evidence,
    Header,
    ScoredSentence,
    ServiceHealth,
    WordProbabilities,
)
from beyond_self.services.deployment import Deployment
from beyond_self.services.registry import fleet_consumers

RECORDINGS = Path(__file__).resolve().parent.parent / "recordings"
CONSUMERS = ["gestures", "objects", "reasoner", "describer"]
ROBOTS = {  # robot -> the recording it replays
    "lab-1": "touch-box.mcap",
    "lab-2": "tap-ball-grasp-box.mcap",
}


class Echo(Service):
    """Says, per robot, how many words messages its run has seen: per-run state."""

    name = "echo"
    subscribes = ("words",)
    publishes = ("description",)
    serves = ()
    fleet = True

    async def setup(self) -> None:
        self.seen = 0
        self.out = self.publisher(self.bus.keys.description, Description, EVENTS)
        self.subscribe(self.bus.keys.words, WordProbabilities, self.on_words, EVENTS)

    def on_words(self, msg: WordProbabilities) -> None:
        self.seen += 1
        text = f"{self.bus.keys.robot} heard {self.seen}"
        self.out.put(
            Description(
                header=self.derive(msg.header, Description),
                segment_id=msg.segment_id,
                sentences=[ScoredSentence(text=text, score=0.0)],
                evidence=Evidence(),
            )
        )


async def wait_until(what: str, condition: Callable[[], bool], timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"waiting for {what}"
        await asyncio.sleep(0.05)


async def test_a_run_per_robot_that_comes_dropped_when_it_leaves() -> None:
    config = private_config()
    fleet_config = config.with_(robot="ws", robots="lab-*")
    with Bus.open(config) as bus:
        fleet = Fleet(Echo, fleet_config, bus=bus, leave_after_s=0.2)
        task = asyncio.get_running_loop().create_task(fleet.run(install_signals=False))
        heard: list[str] = []
        lab1, lab2, other = (bus.for_robot(r) for r in ("lab-1", "lab-2", "other"))
        for robot in (lab1, lab2):
            sub = robot.subscribe(robot.keys.description, Description, EVENTS)

            async def listen(sub: object = sub) -> None:
                async for received in sub:  # type: ignore[attr-defined]
                    heard.append(received.message.sentences[0].text)

            asyncio.get_running_loop().create_task(listen())
        try:
            undeclare = {r: r.declare_token(r.keys.alive("ingest")) for r in (lab1, lab2, other)}
            await wait_until("both lab robots", lambda: fleet.robots == ["lab-1", "lab-2"])
            await bus.wait_alive(lab2.keys.alive("echo"))
            assert await bus.live_tokens("beyond/other/alive/echo") == []  # not its robot
            words = {r: r.publisher(r.keys.words, WordProbabilities, EVENTS) for r in (lab1, lab2)}
            for seg, robot in enumerate([lab1, lab1, lab2]):
                msg = WordProbabilities(
                    header=_header(seg),
                    segment_id=seg,
                    words={},
                    evidence={},
                    action_belief={},
                    final=True,
                )
                words[robot].put(msg)
            await wait_until("three answers", lambda: len(heard) == 3)
            # each robot's count is its own run's: lab-2 heard its first
            assert sorted(heard) == ["lab-1 heard 1", "lab-1 heard 2", "lab-2 heard 1"]
            # the process answers for itself under the workstation's name: every run summed
            (health,) = await bus.query("beyond/ws/health/echo", ServiceHealth)
            assert health.message.messages_in == 3 and health.message.messages_out == 3
            undeclare[lab1]()  # lab-1's source leaves: its run is dropped, lab-2's goes on
            await wait_until("lab-1 dropped", lambda: fleet.robots == ["lab-2"])
            await bus.wait_gone(lab1.keys.alive("echo"))
            await bus.wait_alive(lab2.keys.alive("echo"))
        finally:
            fleet.stop()
            await task
        assert fleet.robots == [] and fleet.failed == {}
    with pytest.raises(InputError, match="own name 'lab-9' is one of the robots"):
        Fleet(Echo, BusConfig(robot="lab-9", robots="lab-*"))


class Voice(Service):
    """A robot's voice, as the speech service: says each description once (by identity),
    and keeps the robot's ledgers (a workstation that takes over resumes from them)."""

    name = "voice"
    subscribes = ("description",)
    publishes = ()
    serves = ()

    def __init__(self, **base: Any) -> None:
        super().__init__(**base)
        # before setup: a loaded machine may start the fleets' runs before this one has asked
        # for its ledgers, and the test reads what was said from then on
        self.said: list[int] = []

    async def setup(self) -> None:
        keys = self.bus.keys
        self.subscribe(keys.description, Description, self.on_description, EVENTS, once=True)

    def on_description(self, msg: Description) -> None:
        self.said.append(msg.segment_id)


TAKEOVER_S = 1.0  # the standby's wait: far above a token's way across one machine


async def test_a_standby_takes_over_a_dead_workstations_robots_and_repeats_nothing() -> None:
    """ws-a serves lab-a*, ws-b lab-b*, each the other's standby. ws-a dies (its session goes,
    tokens and all): ws-b serves lab-a1 too, from the robot's ledgers, and each gesture of
    each robot is said once. ws-a back: still exactly one host per robot."""
    config = private_config()
    a_config = config.with_(robot="ws-a", robots="lab-a*", standby="lab-b*")
    b_config = config.with_(robot="ws-b", robots="lab-b*", standby="lab-a*")
    loop = asyncio.get_running_loop()

    def start(fleet: Fleet) -> asyncio.Task[None]:
        return loop.create_task(fleet.run(install_signals=False))

    with Bus.open(config) as robots, Bus.open(config) as b_bus:
        a_bus = Bus.open(config)
        a = Fleet(Echo, a_config, bus=a_bus, takeover_after_s=TAKEOVER_S)
        b = Fleet(Echo, b_config, bus=b_bus, takeover_after_s=TAKEOVER_S)
        tasks = [start(a), start(b)]
        voices, words = {}, {}
        for name in ("lab-a1", "lab-b1"):
            robot = robots.for_robot(name)
            voices[name] = Voice(bus=robot, health_period=0.05)
            tasks.append(start_service(voices[name]))
            robot.declare_token(robot.keys.alive("ingest"))
            words[name] = robot.publisher(robot.keys.words, WordProbabilities, EVENTS)
        try:
            await wait_until(
                "each its own", lambda: (a.robots, b.robots) == (["lab-a1"], ["lab-b1"])
            )
            for seg in (1, 2):
                for name in voices:
                    words[name].put(final_words(seg))
            await wait_until("two each", lambda: all(len(v.said) == 2 for v in voices.values()))

            tasks[0].cancel()  # ws-a dies: its runs stop, its session closes with its tokens
            a_bus.close()
            await wait_until("ws-b serving both", lambda: b.robots == ["lab-a1", "lab-b1"])
            assert b.takeovers == 1 and a.takeovers == 0
            for name in voices:
                words[name].put(final_words(3))
            await wait_until("three each", lambda: all(3 in v.said for v in voices.values()))

            a_bus = Bus.open(config)  # ws-a back, as its supervisor would start it
            a = Fleet(Echo, a_config, bus=a_bus, takeover_after_s=TAKEOVER_S)
            tasks[0] = start(a)
            await wait_until(
                "ws-a knows who serves lab-a1",
                lambda: bool(a.served_by.get("lab-a1") or b.served_by.get("lab-a1")),
            )
            await wait_until(
                "one host per robot",
                lambda: (
                    len([f for f in (a, b) if "lab-a1" in f.robots]) == 1
                    and len([f for f in (a, b) if "lab-b1" in f.robots]) == 1
                ),
            )
            for name in voices:
                words[name].put(final_words(4))
            await wait_until("four each", lambda: all(4 in v.said for v in voices.values()))
        finally:
            for fleet in (a, b):
                fleet.stop()
            for voice in voices.values():
                voice.stop()
            await asyncio.gather(*tasks, return_exceptions=True)
            a_bus.close()
        for name, voice in voices.items():
            assert voice.said == [1, 2, 3, 4], (name, voice.said)  # each once, none lost


def start_service(service: Service) -> asyncio.Task[None]:
    return asyncio.get_running_loop().create_task(service.run(install_signals=False))


@pytest.mark.parametrize("consumer_returns", [True, False])
async def test_a_standby_stage_takes_over_once_its_consumers_new_runs_are_there(
    consumer_returns: bool,
) -> None:
    """A standby's stage takes a dead host's robot over once the consumer seen serving it has
    a run for it again (sink first: the producer's new run finds its consumers' new instances),
    not after a fixed step per stage; a consumer that does not come back (the standby does not
    run it) is waited for until the latest wait only."""
    config = private_config()
    standby = config.with_(robot="ws-b", robots="lab-b*", standby="lab-a*")
    with Bus.open(config) as robots, Bus.open(config) as dead, Bus.open(config) as bus:
        # coming back, it is the consumer's new run that lets the standby go: the latest wait
        # is then far beyond the test's own
        latest = 60.0 if consumer_returns else 1.0
        fleet = Fleet(Echo, standby, bus=bus, takeover_after_s=0.2, consumers=("sink",),
                      takeover_latest_s=latest)  # fmt: skip
        task = asyncio.get_running_loop().create_task(fleet.run(install_signals=False))
        robot = robots.for_robot("lab-a1")
        sink_key = robot.keys.alive("sink")
        try:
            gone = dead.declare_token(sink_key)  # the dead host's consumer served the robot
            await wait_until("the consumer seen", lambda: "sink" in fleet.consumers_alive.get(
                "lab-a1", set()))  # fmt: skip
            gone()
            await wait_until("the consumer gone", lambda: not fleet.consumers_alive["lab-a1"])
            # the robot unserved only now: the standby's 0.2 s wait cannot end before it has
            # heard of the consumer, however late a loaded machine delivers the tokens
            robot.declare_token(robot.keys.alive("ingest"))
            await wait_until("the standby's wait over", lambda: "lab-a1" in fleet._latest)
            assert fleet.robots == [] and fleet.takeovers == 0  # waiting on the consumer
            if consumer_returns:
                robot.declare_token(sink_key)  # its new run, on any host
            await wait_until("the standby serving lab-a1", lambda: fleet.robots == ["lab-a1"])
            assert fleet.takeovers == 1 and not fleet._latest
        finally:
            fleet.stop()
            await asyncio.gather(task, return_exceptions=True)


def test_each_stage_waits_for_the_fleet_services_it_feeds() -> None:
    """What a standby's stage waits for (`beyond service NAME --robots ...`): the fleet
    services fed by its outputs; the robot's own voice (speech) is not a fleet service."""
    assert fleet_consumers("gestures") == ("objects", "reasoner")
    assert fleet_consumers("objects") == ("reasoner",)
    assert fleet_consumers("reasoner") == ("describer",)
    assert fleet_consumers("describer") == ()


def final_words(seg: int) -> WordProbabilities:
    return WordProbabilities(
        header=_header(seg), segment_id=seg, words={}, evidence={}, action_belief={}, final=True
    )


def _header(seq: int) -> Header:
    return Header(version=1, source="test", seq=seq, stamp=10**18 + seq, correlation="t")


async def play_robots(
    base: BusConfig, recordings: dict[str, Path], record_to: Path | None = None
) -> dict[str, list[str]]:
    """Each robot's source replays its recording at once into the workstation's services;
    each robot's lines, as `beyond up` prints them. With `record_to`, the whole fleet's
    traffic is recorded there meanwhile."""
    robots = {
        robot: Deployment(
            base.with_(robot=robot),
            ["ingest"],
            options={"ingest": {"recording": str(recording)}},
            wait_for=CONSUMERS,
            watcher="monitor",
            clock="recording",
            env={"BEYOND_LOG_FORMAT": "text"},
        )
        for robot, recording in recordings.items()
    }
    lines: dict[str, list[str]] = {robot: [] for robot in recordings}
    monitors: dict[str, PipelineMonitor] = {}
    stop_recording = asyncio.Event()
    recorder = None
    try:
        for robot, side in robots.items():
            monitors[robot] = PipelineMonitor.of(side, await side.open(), lines[robot].append)
            monitors[robot].start()
        if record_to is not None:
            ready = asyncio.Event()
            bus = await next(iter(robots.values())).open()
            recorder = asyncio.get_running_loop().create_task(
                record(bus, ["beyond/lab-$*/**"], record_to, stop=stop_recording, ready=ready)
            )
            await ready.wait()
        await asyncio.gather(*(side.start() for side in robots.values()))
        deadline = time.monotonic() + 300
        while not all(m.done() for m in monitors.values()):
            assert time.monotonic() < deadline, lines
            dead = [n for side in robots.values() for n in side.exited()]
            assert not dead, (dead, [p.lines[-10:] for s in robots.values() for p in s.processes])
            await asyncio.sleep(0.2)
    finally:
        stop_recording.set()
        if recorder is not None:
            await recorder
        for monitor in monitors.values():
            monitor.stop()
        codes = [await side.stop() for side in robots.values()]
    assert all(set(c.values()) == {0} for c in codes), codes
    return lines


@pytest.mark.slow
@pytest.mark.timeout(400)
async def test_one_set_of_services_serves_a_fleet_and_its_replay(tmp_path: Path) -> None:
    """Two robots replay two shipped recordings at once into one process per service on a
    workstation, the fleet's traffic recorded meanwhile: each robot's lines are `beyond
    analyse`'s of its own recording. Then each robot's source replays its part of the fleet's
    recording into the same services (its robot's run started afresh): the same lines again,
    and `beyond analyse --robot` of the fleet's recording agrees."""
    base = private_config()
    started = time.monotonic()
    workstation = Deployment(
        base.with_(robot="ws", robots="lab-*"),
        CONSUMERS,
        clock="recording",
        env={"BEYOND_LOG_FORMAT": "text", LEAVE_ENV: "0.5"},
    )
    fleet = tmp_path / "fleet.mcap"
    counted = PipelineMonitor.of(workstation, await workstation.open(), lambda _line: None)
    try:
        counted.start()  # what the workstation's `beyond up` says at the end
        await workstation.start()
        live = await play_robots(base, {r: RECORDINGS / f for r, f in ROBOTS.items()}, fleet)
        first = time.monotonic() - started
        said = {r: sum(1 for line in live[r] if line.endswith('"')) for r in ROBOTS}
        deadline = time.monotonic() + 30
        while counted.fleet is not None and counted.fleet.counts()[0] < sum(said.values()):
            assert time.monotonic() < deadline, counted.summary()
            await asyncio.sleep(0.1)
        each = ", ".join(f"{r} {n} of {n}" for r, n in sorted(said.items()))
        n = sum(said.values())
        assert counted.summary() == f"{n} of {n} gesture(s) described ({each})"
        bus = await workstation.open()
        for robot in ROBOTS:  # their sources have left: the runs are dropped
            await bus.wait_gone(f"beyond/{robot}/alive/gestures", timeout=30)
        replayed = await play_robots(base, dict.fromkeys(ROBOTS, fleet))
        assert not workstation.exited()
    finally:
        counted.stop()
        codes = await workstation.stop()
    took = time.monotonic() - started
    print(f"{len(ROBOTS)} robots on one workstation: {first:.1f} s; and the replay: {took:.1f} s")
    assert set(codes.values()) == {0}, codes
    for robot, recording in ROBOTS.items():
        offline = default_run(_inputs(RECORDINGS / recording, "right_hand", "torso")).lines
        assert offline and live[robot] == offline, (robot, live[robot], offline)
        assert replayed[robot] == offline, (robot, replayed[robot], offline)
    # offline, the fleet's recording gives a robot its own part (one robot: each costs seconds)
    from_fleet = default_run(_inputs(fleet, "right_hand", "torso", robot="lab-1")).lines
    assert from_fleet == live["lab-1"]
    with pytest.raises(InputError, match=r"fleet's recording .* choose one with --robot"):
        _inputs(fleet, "right_hand", "torso")


def test_fleet_compose_file_runs_each_service_once_for_the_fleet() -> None:
    yaml = pytest.importorskip("yaml")
    from beyond_self.services.registry import PROFILES, service_class

    services = yaml.safe_load((RECORDINGS.parent / "docker-compose.fleet.yml").read_text())
    services = services["services"]
    for profile in ("fleet-workstation", "fleet-robot"):
        named = {n for n, c in services.items() if profile in c["profiles"] and n != "router"}
        assert named == set(PROFILES[profile]), profile
    for name in PROFILES["fleet-workstation"]:
        env = services[name]["environment"]
        assert service_class(name).fleet and env["BEYOND_ROBOTS"], name
    for name in PROFILES["fleet-robot"]:
        assert not service_class(name).fleet
        assert "BEYOND_ROBOTS" not in services[name]["environment"], name
    waits = services["ingest"]["command"][-1]  # the robot's source waits for the workstation
    assert all(n in waits for n in PROFILES["fleet-workstation"])
