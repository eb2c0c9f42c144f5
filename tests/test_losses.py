"""Loss is loud (issue 39 point 5, issue 42 point 1): a gesture cut because its frames were lost,
or sensor frames dropped as stale, are said in `beyond up`'s summary and make it exit 3; "2 of
2 described" never hides a cut."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable

import pytest
from busutil_net import private_config, serve_cut_predecessor

import beyond_self.schemas as s
from beyond_self.cognition.gestures import synthesize_continuous
from beyond_self.commands import up
from beyond_self.core.errors import InputError
from beyond_self.monitor import PipelineMonitor
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.clock import Clock
from beyond_self.runtime.self_report import RESTARTS_ENV
from beyond_self.services.deployment import Ending
from beyond_self.services.registry import service_class


def header(seq: int, stamp: int, source: str = "test") -> s.Header:
    return s.Header(version=1, source=source, seq=seq, stamp=stamp)


def segment(seq: int, event: str, segment_id: int, **more: object) -> s.GestureSegment:
    return s.GestureSegment(
        header=s.GestureSegment.original_header("gestures", seq, 1000 + seq),
        event=event,  # type: ignore[arg-type]
        segment_id=segment_id, frame=10 * seq, start_stamp=1000,
        end_stamp=1000 + seq if event == "end" else None, **more,  # type: ignore[arg-type]
    )  # fmt: skip


def health(service: str, stale: int, restarts: int) -> s.ServiceHealth:
    return s.ServiceHealth(
        header=s.ServiceHealth.original_header(service, 0, 1), service=service, uptime_s=1.0,
        messages_in=1, messages_out=1, dropped=0, malformed=0, errors=0, restarts=restarts,
        stale=stale,
    )  # fmt: skip


@pytest.fixture
async def monitor() -> AsyncIterator[PipelineMonitor]:
    with Bus.open(private_config()) as bus:
        yield PipelineMonitor(bus, lambda _line: None)


def described(monitor: PipelineMonitor, segment_id: int, seq: int) -> None:
    monitor.on_segment(segment(seq, "start", segment_id))
    monitor.on_segment(segment(seq + 1, "end", segment_id))
    monitor.on_description(description(seq, segment_id, 1000 + seq))


def description(seq: int, segment_id: int, stamp: int) -> s.Description:
    """A final description of `segment_id`, as the describer publishes one."""
    return s.Description(
        header=s.Description.original_header("describer", seq, stamp),
        segment_id=segment_id,
        sentences=[s.ScoredSentence(text="he taps the box", score=0.0)],
        evidence=s.Evidence(),
        final=True,
    )


def test_a_cut_gesture_is_counted_named_and_is_a_loss(monitor: PipelineMonitor) -> None:
    described(monitor, 1, 1)
    described(monitor, 3, 10)
    monitor.on_segment(segment(5, "start", 2))
    monitor.on_segment(segment(6, "cancel", 2, reason="its frames before 7 are gone", cut=True))
    monitor.on_segment(segment(7, "start", 4))
    monitor.on_segment(segment(8, "cancel", 4, reason="too short"))  # withdrawn: not a gesture
    assert monitor.summary() == (
        "2 of 3 gesture(s) described, 1 cut (frames lost: gesture 2: its frames before 7 are gone)"
    )
    assert monitor.losses() == ["1 cut (frames lost: gesture 2: its frames before 7 are gone)"]


def test_an_ended_gesture_passed_over_is_a_loss(monitor: PipelineMonitor) -> None:
    """Gesture 1 ended but its final belief never came (lost on a cut link); gesture 2 was
    described whole: 1 is passed over, and the summary and exit status say it was lost."""
    monitor.on_segment(segment(1, "start", 1))
    monitor.on_segment(segment(2, "end", 1))
    monitor.on_segment(segment(3, "start", 2))
    monitor.on_segment(segment(4, "end", 2))
    monitor.report.believed(2)
    monitor.report.recognised(2, {"tap": 0.9, "grasp": 0.1}, {"Shape": "circle"})
    assert monitor.losses() == []  # gesture 1 may still come
    monitor.on_description(description(5, 2, 1005))
    assert monitor.report.gestures[2].printed and monitor.report.gestures[1].skipped
    (lost,) = monitor.losses()
    assert lost.startswith("1 ended but not described (gesture 1: an input it needed was lost")
    assert monitor.summary() == f"1 of 2 gesture(s) described, {lost}"


def test_nothing_lost_is_the_plain_summary(monitor: PipelineMonitor) -> None:
    described(monitor, 1, 1)
    described(monitor, 2, 10)
    monitor.on_segment(segment(20, "start", 3))
    monitor.on_segment(segment(21, "cancel", 3, reason="the stream ended"))
    monitor.on_health(health("gestures", stale=0, restarts=0))
    assert monitor.summary() == "2 of 2 gesture(s) described"
    assert monitor.losses() == []


def test_stale_frames_add_up_over_restarts(monitor: PipelineMonitor) -> None:
    """Each instance counts from 0; a report repeated, or an older one arriving late, does not
    count twice."""
    for service, stale, restarts in [
        ("gestures", 400, 0), ("gestures", 474, 0), ("gestures", 470, 0),
        ("gestures", 2, 1), ("objects", 5, 0),
    ]:  # fmt: skip
        monitor.on_health(health(service, stale, restarts))
    assert monitor.losses() == ["481 sensor frame(s) dropped as stale (gestures 476, objects 5)"]
    assert monitor.summary().endswith(
        "0 of 0 gesture(s) described, 481 sensor frame(s) dropped as stale (gestures 476, "
        "objects 5)"
    )


def test_up_exits_3_on_a_loss_and_damage_or_failure_come_first() -> None:
    assert up.exit_status(Ending("done"), damage="", lost=[]) == 0
    assert up.exit_status(Ending("done"), damage="", lost=["1 cut"]) == up.LOST == 3
    assert up.exit_status(Ending("stopped"), damage="", lost=["1 cut"]) == 3
    assert up.exit_status(Ending("timeout"), damage="", lost=["1 cut"]) == 1
    with pytest.raises(InputError, match="2 chunks lost"):
        up.exit_status(Ending("done"), damage="2 chunks lost", lost=["1 cut"])


async def until(condition: Callable[[], bool], what: str, timeout: float = 20.0) -> None:
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while not condition():
        assert loop.time() < deadline, what
        await asyncio.sleep(0.02)


async def test_the_streamers_cut_reaches_the_summary(monkeypatch: pytest.MonkeyPatch) -> None:
    """End to end on a bus: a restarted streamer whose source's cache starts after its
    predecessor's checkpoint cannot rebuild gesture 2 (its start was told, its end never was):
    it cancels it as cut, with the reason, and the monitor's summary counts it."""
    monkeypatch.setenv(RESTARTS_ENV, "1")
    config = private_config()
    first = 10**18
    with Bus.open(config) as others, Bus.open(config) as bus:
        serve_cut_predecessor(others, first)
        monitor = PipelineMonitor(others, lambda _line: None)
        monitor.start()
        service = service_class("gestures")(bus=bus, health_period=0.05)
        task = asyncio.create_task(service.run(install_signals=False))
        try:
            await asyncio.wait_for(service.started.wait(), 20)
            pub = others.publisher(others.keys.skeleton, s.SkeletonFrame)
            await pub.wait_matching(timeout=10)
            stream = synthesize_continuous(["tap"], seed=5)
            for i in range(5, 40):  # the restarted source's cache: the frames before are gone
                joints = {
                    n: s.Joint(position=(float(p[i, 0]), float(p[i, 1]), float(p[i, 2])))
                    for n, p in stream.joints.items()
                }
                pub.put(s.SkeletonFrame(header=header(i, first + i * 33_333_333), frame=i + 1,
                                        joints=joints))  # fmt: skip
            await until(lambda: 2 in monitor.cut, "the monitor never heard gesture 2 was cut")
            # out of order: before the last handled, at a stamp never read (a repeat is no loss)
            old = first + 5 * 33_333_333 + 1
            pub.put(s.SkeletonFrame(header=header(99, old), frame=6, joints=joints))
            await until(lambda: bool(monitor.stale), "the monitor never heard of the stale frame")
        finally:
            monitor.stop()
            service.stop()
            await asyncio.wait_for(task, 10)
    cut = f"gesture 2: its frames before {first + 5 * 33_333_333} are gone"
    assert monitor.losses() == [
        f"1 cut (frames lost: {cut} (source and streamer restarted))",
        "1 sensor frame(s) dropped as stale (gestures 1)",
    ]
    assert "0 of 1 gesture(s) described, 1 cut" in monitor.summary()


async def test_a_fleet_workstation_counts_the_gestures_of_the_robots_it_serves() -> None:
    """Issue 42: a fleet workstation's summary said "0 of 0 gesture(s) described" though it
    described them: its own name has no gestures, its robots' keys do. A message received
    twice (from a cache) counts once; a robot outside the pattern does not count."""
    config = private_config()
    with Bus.open(config.with_(robot="ws-1")) as ws, Bus.open(config) as robots:
        monitor = PipelineMonitor(ws, lambda _line: None, robots=["lab-$*"])
        monitor.start()
        pubs = {}
        for robot in ("lab-1", "lab-2", "other"):
            keys = robots.for_robot(robot).keys
            pubs[robot] = (
                robots.publisher(keys.gesture_segment, s.GestureSegment),
                robots.publisher(keys.description, s.Description),
            )
        for robot in ("lab-1", "lab-2"):  # none subscribes to "other": the pattern is not it
            for pub in pubs[robot]:
                await pub.wait_matching(timeout=10)
        plan = {"lab-1": [1, 2], "lab-2": [1], "other": [1, 2, 3]}
        for robot, ids in plan.items():
            segments, descriptions = pubs[robot]
            for n in ids:
                for _ in range(2):  # again, as a cache would
                    segments.put(segment(n, "start", n))
                    segments.put(segment(n + 1, "end", n))
                if (robot, n) != ("lab-1", 2):  # its description has not come
                    descriptions.put(description(n, n, 2000 + n))
        pubs["lab-2"][0].put(segment(7, "start", 2))
        pubs["lab-2"][0].put(segment(8, "cancel", 2, reason="its frames are gone", cut=True))
        fleet = monitor.fleet
        assert fleet is not None
        await until(lambda: fleet.counts() == (2, 4), f"the tally: {fleet.robots}")
        monitor.stop()
    assert monitor.summary() == (
        "2 of 4 gesture(s) described (lab-1 1 of 2, lab-2 1 of 2), 1 cut (frames lost: "
        "lab-2 gesture 2: its frames are gone)"
    )
    assert set(fleet.robots) == {"lab-1", "lab-2"}


def test_frames_a_replay_skipped_are_not_said_to_be_a_live_cameras(
    monitor: PipelineMonitor,
) -> None:
    """A fleet robot replaying a recording: the workstation's segmenter skips frames as for a
    live camera; the summary says so, and not that the camera was live."""
    monitor.frames_described, monitor.frames_skipped = 90, 10
    assert monitor.summary().endswith(
        "; 10 of 100 camera frames not described, to keep up with the live camera (every "
        "gesture used them all)"
    )
    monitor.clock = Clock("recording")
    assert monitor.summary().endswith(
        "; 10 of 100 camera frames not described, to keep up with the replay, as for a live "
        "camera (every gesture used them all)"
    )
