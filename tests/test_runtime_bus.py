"""Typed pub/sub, the thread-to-loop inbox, query/reply, liveliness, and the service base."""

from __future__ import annotations

import asyncio
import signal
import subprocess
import sys
import threading

import msgspec
import pytest
from busutil_net import EXAMPLES, env_for, health_report, private_config, skeleton_frames

import beyond_self.schemas as s
from beyond_self.runtime.bus.inbox import Inbox
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.service import Service


async def test_inbox_hands_items_from_threads_in_order_and_counts_drops() -> None:
    loop = asyncio.get_running_loop()
    inbox: Inbox[int] = Inbox(loop, maxsize=1000)
    threads = [threading.Thread(target=lambda: [inbox.push(i) for i in range(500)])]
    for t in threads:
        t.start()
    got = [await inbox.get(timeout=5) for _ in range(500)]
    assert got == list(range(500))
    small: Inbox[int] = Inbox(loop, maxsize=3)
    for i in range(10):
        small.push(i)
    assert small.dropped == 7
    assert [await small.get(1) for _ in range(3)] == [7, 8, 9]
    with pytest.raises(TimeoutError):
        await small.get(timeout=0.05)
    small.close()
    with pytest.raises(EOFError):
        await small.get(timeout=1)


@pytest.fixture
async def buses():
    config = private_config()
    a, b = Bus.open(config), Bus.open(config)
    yield a, b
    a.close()
    b.close()


async def test_typed_pub_sub_across_sessions(buses) -> None:
    a, b = buses
    sub = a.subscribe(a.keys.skeleton, s.SkeletonFrame)
    pub = b.publisher(b.keys.skeleton, s.SkeletonFrame)
    await pub.wait_matching(timeout=10)
    frames = skeleton_frames(50)
    for f in frames:
        pub.put(f)
    got = [await sub.recv(timeout=5) for _ in frames]
    assert [r.message for r in got] == frames
    assert {r.key for r in got} == {a.keys.skeleton}
    with pytest.raises(TypeError):
        pub.put(
            s.GestureSegment(
                header=frames[0].header, event="start", segment_id=0, frame=0, start_stamp=0
            )
        )


async def test_malformed_payloads_are_counted_and_skipped(buses) -> None:
    a, b = buses
    seen: list[str] = []
    sub = a.subscribe(
        a.keys.skeleton, s.SkeletonFrame, on_malformed=lambda k, e: seen.append(str(e))
    )
    pub = b.publisher(b.keys.skeleton, s.SkeletonFrame)
    await pub.wait_matching(timeout=10)
    pub.put_bytes(b"\xff garbage")
    pub.put_bytes(msgspec.msgpack.encode({"type": "SkeletonFrame"}))
    good = skeleton_frames(1)[0]
    pub.put(good)
    assert (await sub.recv(timeout=5)).message == good
    assert sub.malformed == 2
    assert all(a.keys.skeleton in text for text in seen)


async def test_query_reply_and_liveliness(buses) -> None:
    a, b = buses
    health = health_report("q")

    async def answer(key: str, request: None) -> list[tuple[str, s.Message]]:
        return [(b.keys.health("q"), health)]

    b.queryable(b.keys.health("q"), None, answer)
    b.declare_token(b.keys.alive("q"))
    alive = await a.wait_alive(a.keys.alive(), timeout=10)
    assert alive == {a.keys.alive("q")}
    replies = await a.query(a.keys.health(), s.ServiceHealth, timeout=5)
    assert [r.message for r in replies] == [health]
    assert replies[0].key == a.keys.health("q")


class Echo(Service):
    """Publishes the frame number of each skeleton as a GestureSegment start."""

    name = "echo"

    async def setup(self) -> None:
        self.out = self.publisher(self.bus.keys.gesture_segment, s.GestureSegment)
        self.subscribe(self.bus.keys.skeleton, s.SkeletonFrame, self.on_frame)
        self.subscribe(self.bus.keys.objects, s.DetectedObjects, self.on_objects)

    def on_frame(self, frame: s.SkeletonFrame) -> None:
        if frame.frame >= 1_000_000:
            raise s.SchemaError("frame too far")  # an InputError from a handler
        self.out.put(
            s.GestureSegment(
                header=self.derive(frame.header, s.GestureSegment),
                event="start",
                segment_id=frame.frame,
                frame=frame.frame,
                start_stamp=frame.header.stamp,
            )
        )

    async def on_objects(self, objects: s.DetectedObjects) -> None:
        await asyncio.sleep(0)


async def test_service_survives_garbage_on_every_subscribed_key(buses, caplog) -> None:
    a, b = buses
    service = Echo(bus=b, health_period=0.05)
    task = asyncio.create_task(service.run(install_signals=False))
    await asyncio.wait_for(service.started.wait(), 10)
    out = a.subscribe(a.keys.gesture_segment, s.GestureSegment)
    inputs = service.health_report().inputs
    assert inputs == sorted([a.keys.skeleton, a.keys.objects])
    garbage = [
        b"",
        b"\x00\x01\x02",
        msgspec.msgpack.encode({"type": "Nope", "header": 3}),
        s.encode(
            s.GestureSegment(
                header=skeleton_frames(1)[0].header,
                event="start",
                segment_id=0,
                frame=0,
                start_stamp=0,
            )
        ),
    ]
    publishers = {}
    for key in inputs:
        publishers[key] = a.publisher(key, s.SkeletonFrame)
        await publishers[key].wait_matching(timeout=10)
        for payload in garbage:
            publishers[key].put_bytes(payload)
        publishers[key].put_bytes(garbage[1])  # same key and reason again: logged once
    frames = skeleton_frames(3)
    bad = msgspec.structs.replace(frames[0], frame=1_000_000)
    publishers[a.keys.skeleton].put(bad)
    # valid shape, impossible meaning: the schema's bounds refuse it (malformed, not an error)
    publishers[a.keys.skeleton].put(msgspec.structs.replace(frames[0], frame=-1))
    for f in frames:
        publishers[a.keys.skeleton].put(f)
    got = [(await out.recv(timeout=5)).message for _ in frames]
    assert [g.segment_id for g in got] == [0, 1, 2]
    assert [g.header.stamp for g in got] == [f.header.stamp for f in frames]
    expected = 2 * (len(garbage) + 1) + 1
    loop = asyncio.get_running_loop()
    deadline = loop.time() + 20  # the other key's garbage may still be in flight
    while service.health_report().malformed < expected and loop.time() < deadline:
        await asyncio.sleep(0.02)
    health = service.health_report()
    assert health.malformed == expected
    assert health.errors == 1
    bad_input = [r for r in caplog.records if r.getMessage() == "bad input skipped"]
    assert len(bad_input) == 1 and "frame too far" in bad_input[0].fields["reason"]
    assert health.messages_in == 4 and health.messages_out == 3
    logged = [r for r in caplog.records if r.getMessage() == "malformed payload skipped"]
    assert len(logged) == 2 * len(garbage) + 1  # once per (key, reason)
    assert any("Expected `int` >= 0 - at `$.frame`" in r.fields["reason"] for r in logged)
    assert all(r.fields["key"] in inputs and r.fields["reason"] for r in logged)
    # its health is published periodically and answered on query
    replies = await a.query(a.keys.health("echo"), s.ServiceHealth, timeout=5)
    assert replies[0].message.malformed == health.malformed
    service.stop()
    await asyncio.wait_for(task, 10)


async def test_service_process_stops_cleanly_on_sigterm() -> None:
    config = private_config()
    with Bus.open(config) as bus:
        proc = subprocess.Popen(
            [sys.executable, str(EXAMPLES / "doubler.py")],
            env=env_for(config),
            stderr=subprocess.PIPE,
            text=True,
        )
        try:
            await bus.wait_alive(bus.keys.alive("doubler"), timeout=20)
            gone = asyncio.get_running_loop().create_future()

            def on_change(sample) -> None:  # liveliness DELETE when the token is undeclared
                if str(sample.kind) == "SampleKind.DELETE" and not gone.done():
                    gone.get_loop().call_soon_threadsafe(gone.set_result, True)

            watcher = bus.session.liveliness().declare_subscriber(
                bus.keys.alive("doubler"), on_change
            )
            proc.send_signal(signal.SIGTERM)
            assert await asyncio.wait_for(gone, 10)
            assert proc.wait(timeout=10) == 0
            watcher.undeclare()
        finally:
            if proc.poll() is None:
                proc.kill()
        err = proc.stderr.read() if proc.stderr else ""
        assert '"event": "stopped"' in err


async def test_progress_after_each_message_goes_out_only_while_someone_subscribes(buses) -> None:
    """Live, nobody paces on a service's Progress: building and putting it for every frame was
    a tenth of a fleet's gesture streamer's time (runtime.progress)."""
    from beyond_self.runtime.progress import ProgressReport

    a, b = buses
    report = ProgressReport("gestures", lambda cls: s.Header(version=1, source="t", seq=0, stamp=0))
    report.pace(a.keys.skeleton)
    report.open(a, report.report({}, {}, {}))
    assert not report.wanted

    async def until(wanted: bool) -> None:
        for _ in range(500):
            if report.wanted is wanted:
                return
            await asyncio.sleep(0.02)
        raise AssertionError(f"wanted stayed {report.wanted} for 10 s")

    sub = b.subscribe(b.keys.progress("gestures"), s.Progress)
    await until(True)
    sub.close()
    await until(False)
