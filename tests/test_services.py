"""The pipeline's services: garbage on every key they subscribe to is counted and skipped, and
each service still does its job afterwards."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator

import msgspec
import pytest
from busutil_net import private_config, serve_cut_predecessor

import beyond_self.schemas as s
from beyond_self.cognition.gestures import synthesize_continuous
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.resilience.ledger import Position
from beyond_self.runtime.self_report import RESTARTS_ENV
from beyond_self.services.registry import SERVICES, service_class

GARBAGE = [b"", b"\x00\x01\x02", msgspec.msgpack.encode({"type": "Nope", "header": 3})]


@pytest.fixture
async def bus() -> AsyncIterator[Bus]:
    b = Bus.open(private_config())
    yield b
    b.close()


def _header(seq: int, stamp: int) -> s.Header:
    return s.Header(version=1, source="test", seq=seq, stamp=stamp, correlation=f"test/{seq}")


async def _start(name: str, bus: Bus, **options: object) -> object:
    service = service_class(name)(bus=bus, health_period=0.05, **options)
    task = asyncio.create_task(service.run(install_signals=False))
    await asyncio.wait_for(service.started.wait(), 20)
    service._test_task = task  # type: ignore[attr-defined]
    return service


async def _stop(service: object) -> None:
    service.stop()  # type: ignore[attr-defined]
    await asyncio.wait_for(service._test_task, 10)  # type: ignore[attr-defined]


@pytest.mark.parametrize("name", [n for n in SERVICES if n != "ingest"])
async def test_garbage_on_every_input_is_counted_and_skipped(name: str, bus: Bus) -> None:
    service = await _start(name, bus)
    inputs = service.health_report().inputs  # type: ignore[attr-defined]
    assert inputs, f"{name} subscribes to nothing"
    for key in inputs:
        pub = bus.publisher(key, s.SkeletonFrame)
        await pub.wait_matching(timeout=10)
        for payload in GARBAGE:
            pub.put_bytes(payload)
    expected = len(inputs) * len(GARBAGE)
    for _ in range(200):
        if service.health_report().malformed >= expected:  # type: ignore[attr-defined]
            break
        await asyncio.sleep(0.02)
    health = service.health_report()  # type: ignore[attr-defined]
    assert health.malformed == expected
    assert not service._test_task.done()  # type: ignore[attr-defined]
    await _stop(service)


async def test_describer_still_describes_after_garbage(bus: Bus) -> None:
    service = await _start("describer", bus)
    out = bus.subscribe(bus.keys.description, s.Description)
    pub = bus.publisher(bus.keys.words, s.WordProbabilities)
    await pub.wait_matching(timeout=10)
    pub.put_bytes(b"garbage")
    from beyond_self.cognition.grammar import DEFAULT_GRAMMAR

    words = {w: 0.5 for w in DEFAULT_GRAMMAR.vocabulary}
    words.update({"taps": 0.99, "he": 0.99, "the": 0.99, "ball": 0.99, "rolls": 0.99, "and": 0.99})
    pub.put(s.WordProbabilities(header=_header(1, 10), segment_id=7, words=words))
    got = (await out.recv(timeout=10)).message
    assert got.segment_id == 7 and got.final
    assert got.sentences[0].text == "he taps the ball and the ball rolls"
    assert service.health_report().malformed == 1  # type: ignore[attr-defined]
    await _stop(service)


async def test_gesture_streamer_segments_and_recognises_a_synthetic_stream(bus: Bus) -> None:
    service = await _start("gestures", bus)
    posteriors = bus.subscribe(bus.keys.gesture_posterior, s.ActionPosterior)
    segments = bus.subscribe(bus.keys.gesture_segment, s.GestureSegment)
    pub = bus.publisher(bus.keys.skeleton, s.SkeletonFrame)
    await pub.wait_matching(timeout=10)
    stream = synthesize_continuous(["tap", "grasp"], seed=5)
    far = {"right_hand": s.Joint(position=(40.0, 0.0, 2.0)), "torso": s.Joint(position=(0, 0, 2))}
    for i in range(stream.n_frames):
        joints = {
            n: s.Joint(position=(float(p[i, 0]), float(p[i, 1]), float(p[i, 2])))
            for n, p in stream.joints.items()
        }
        stamp = 10**18 + i * 33_333_333
        if i in (10, 200):  # a hand 40 m away: not a person's, counted and skipped
            pub.put(s.SkeletonFrame(header=_header(i, stamp - 1), frame=i + 1, joints=far))
        pub.put(s.SkeletonFrame(header=_header(i, stamp), frame=i + 1, joints=joints))
    events = [(await segments.recv(timeout=20)).message for _ in range(4)]
    assert [(e.event, e.segment_id) for e in events] == [
        ("start", 1),
        ("end", 1),
        ("start", 2),
        ("end", 2),
    ]
    for e, truth in zip(events[::2], stream.gestures, strict=True):  # start near the true start
        assert 0 <= e.frame - (truth.start + 1) <= 20  # as the hand leaves its rest
    finals = []
    while len(finals) < 2:
        p = (await posteriors.recv(timeout=20)).message
        if p.final:
            finals.append(p.actions[max(range(3), key=p.posterior.__getitem__)])
    assert finals == ["tap", "grasp"]
    health = service.health_report()  # type: ignore[attr-defined]
    assert health.errors == 2 and "body units from the torso" in health.last_error
    await _stop(service)


async def test_reasoner_answers_ad_hoc_queries_and_rejects_bad_ones(bus: Bus) -> None:
    service = await _start("reasoner", bus)
    q = s.AffordanceQuery(
        header=_header(0, 0), query=["ObjVel"], evidence={"Shape": "circle"},
        gesture={"grasp": 0.0, "tap": 1.0, "touch": 0.0},
    )  # fmt: skip
    replies = await bus.query(bus.keys.ask, s.AffordanceAnswer, payload=q, timeout=5)
    dist = {r.assignment["ObjVel"]: r.p for r in replies[0].message.rows}
    model = service.model  # type: ignore[attr-defined]
    direct = model.query("ObjVel", {"Shape": "circle", "Action": "tap"}).marginal("ObjVel")
    assert dist == pytest.approx(direct, abs=1e-12)
    bad = s.AffordanceQuery(header=_header(1, 0), query=["Nope"])
    from beyond_self.core.errors import InputError

    with pytest.raises(InputError, match="valid: Action"):
        await bus.query(bus.keys.ask, s.AffordanceAnswer, payload=bad, timeout=5)
    await _stop(service)


async def test_on_a_replay_health_is_on_the_streams_clock_also_before_it_and_paused(
    bus: Bus,
) -> None:
    """runtime.clock: a service on the recording's clock publishes health every period whatever
    the stream does (it shows the service is alive): stamped 0 before the player's first tick,
    then with the stream's time, which stands still while the player is paused."""
    from beyond_self.runtime.clock import Clock

    health = bus.subscribe(bus.keys.health("describer"), s.ServiceHealth)
    service = await _start("describer", bus, clock=Clock("recording"))
    assert (await health.recv(timeout=10)).message.header.stamp == 0
    ticks = bus.publisher(bus.keys.clock, s.StreamClock)
    await ticks.wait_matching(timeout=10)
    stream_time = 1_546_300_801_433_333_333
    ticks.put(s.StreamClock(header=_header(0, stream_time)))
    for _ in range(200):
        if (await health.recv(timeout=10)).message.header.stamp == stream_time:
            break
    else:
        raise AssertionError("health never took the stream's time")
    paused = [(await health.recv(timeout=10)).message.header.stamp for _ in range(3)]
    assert paused == [stream_time] * 3  # no tick: the clock stands still, health goes on
    await _stop(service)


async def test_a_restarted_streamer_without_its_checkpoints_frames_cancels_the_gesture_under_way(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Source and streamer both restarted: the skeleton cache starts after the predecessor's
    checkpoint, so gesture 2, whose start the reasoner has and whose end it never got, cannot
    be rebuilt. The successor cancels it (consumers would wait on it for ever) and numbers on
    after it, its events counting on from its predecessor's."""
    monkeypatch.setenv(RESTARTS_ENV, "1")
    config = private_config()
    first = 10**18
    with Bus.open(config) as others, Bus.open(config) as bus:
        key = bus.keys.gesture_segment
        serve_cut_predecessor(others, first)
        service = await _start("gestures", bus)
        segments = others.subscribe(key, s.GestureSegment)
        pub = others.publisher(others.keys.skeleton, s.SkeletonFrame)
        await pub.wait_matching(timeout=10)
        stream = synthesize_continuous(["tap", "grasp"], seed=5)
        for i in range(5, stream.n_frames):  # the restarted source's cache: frame 0 is gone
            joints = {
                n: s.Joint(position=(float(p[i, 0]), float(p[i, 1]), float(p[i, 2])))
                for n, p in stream.joints.items()
            }
            pub.put(s.SkeletonFrame(header=_header(i, first + i * 33_333_333), frame=i + 1,
                                    joints=joints))  # fmt: skip
        events = [(await segments.recv(timeout=20)).message for _ in range(5)]
        assert [(e.event, e.segment_id, e.event_seq) for e in events] == [
            ("cancel", 2, 4),
            ("start", 3, 5),
            ("end", 3, 6),
            ("start", 4, 7),
            ("end", 4, 8),
        ]
        assert "gestures cut [2]" in service.health_report().last_error  # type: ignore[attr-defined]
        await _stop(service)


@pytest.mark.parametrize(("said", "expected"), [([1], 1_000), ([1, 2], 5_000)])
async def test_a_successor_object_segmenter_goes_back_for_a_gesture_not_yet_said(
    monkeypatch: pytest.MonkeyPatch, said: list[int], expected: int
) -> None:
    """Taken over: the predecessor's newest snapshot (restart point, camera stamp 5000) is past
    gesture 2's frames, whose description died with the workstation (the speech service said
    only 1). The gesture streamer's successor derives gesture 2 again, so the object
    segmenter's goes back to the newest snapshot before gesture 2 started (after 1 gesture); once
    2 is said, to the newest."""
    monkeypatch.setenv(RESTARTS_ENV, "1")
    config = private_config()
    with Bus.open(config) as others, Bus.open(config) as bus:
        said_key = bus.keys.description
        kept = [
            s.Ledger(
                header=s.Ledger.original_header("objects", 9, 1), service="objects",
                resume_stamps={"stamp": 5_000, "stamp@0": 200, "stamp@1": 1_000},
                resume={"gestures": 2, "gestures@0": 0, "gestures@1": 1},
            ),
            s.Ledger(
                header=s.Ledger.original_header("speech", 9, 1), service="speech",
                handled={said_key: {"description": [(n, 0, 0) for n in said]}},
            ),
        ]  # fmt: skip

        async def answer(_key: str, _request: None) -> list[tuple[str, s.Message]]:
            return [(others.keys.ledger(m.service), m) for m in kept]

        others.queryable(others.keys.ledger(), None, answer)
        service = await _start("objects", bus)
        assert service._gates[bus.keys.camera].start == expected  # where its input starts
        assert service.watch.gestures_started == (1 if expected == 1_000 else 2)  # type: ignore[attr-defined]
        # a gesture that starts now: the watch's point after it is told to a next successor
        pub = others.publisher(others.keys.gesture_segment, s.GestureSegment)
        await pub.wait_matching(timeout=10)
        header = s.GestureSegment.original_header("gestures", 3, 7_000)
        pub.put(s.GestureSegment(header=header, event_seq=5, event="start", segment_id=3,
                                 frame=210, start_stamp=7_000))  # fmt: skip
        for _ in range(500):
            if "stamp@3" in service._ledgers.resume_stamps:  # type: ignore[attr-defined]
                break
            await asyncio.sleep(0.02)
        stamps = service._ledgers.resume_stamps  # type: ignore[attr-defined]
        assert stamps["stamp@0"] == 200 and stamps["stamp@1"] == 1_000
        assert 0 <= stamps["stamp@3"] <= 7_000, stamps  # after 3 gestures: gesture 4's point
        positions = service._ledgers.positions  # type: ignore[attr-defined]
        camera = others.keys.camera
        assert positions[Position(camera, 4)] == stamps["stamp@3"]  # where 4 needs it from
        # gesture 3 again: from the newest point before it started, the restored one's or older
        assert positions[Position(camera, 2)] <= expected and Position(camera, 3) not in positions
        await _stop(service)


def test_a_fleets_robots_report_at_phases_of_their_own_spread_over_the_period() -> None:
    """runtime.service.report_phase: the same phase for a robot every time, and a fleet's
    robots spread over the whole period (in step, they built every robot's health and ledger
    in one burst each second)."""
    from beyond_self.runtime.service import report_phase

    robots = [f"lab-{k}" for k in range(64)]
    phases = [report_phase(r) for r in robots]
    assert phases == [report_phase(r) for r in robots]
    assert all(0 <= p < 1 for p in phases)
    tenths = {int(p * 10) for p in phases}
    assert len(tenths) == 10, sorted(phases)  # every tenth of the period has some robots
    assert max(sum(int(p * 10) == t for p in phases) for t in tenths) <= 16
