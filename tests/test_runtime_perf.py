"""The fast paths of the bus, checked for behaviour (no timing): subscriptions fed by a Zenoh
channel and a drain thread, eventfd wake-ups, batched hand-off, publishers and replay encoding
into a reused buffer. Speed itself is measured by bench/bus.py."""

from __future__ import annotations

import asyncio
import os
import threading
from pathlib import Path

import pytest
from busutil_net import private_config, skeleton_frames

import beyond_self.schemas as s
from beyond_self.runtime.bus.delivery import Delivery
from beyond_self.runtime.bus.inbox import Inbox
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.recording.replay import replay
from beyond_self.runtime.recording.writer import RecordingWriter
from beyond_self.schemas.codec import encode, encode_into, wire_encoding


def camera_frame(seq: int, width: int = 32, height: int = 24) -> s.CameraFrame:
    header = s.Header(version=1, source="cam", seq=seq, stamp=1_700_000_000_000_000_000 + seq)
    data = bytes((seq + i) % 256 for i in range(width * height * 3))
    return s.CameraFrame.build(header, width, height, data)


async def wait_until(condition, timeout: float = 10.0) -> None:  # type: ignore[no-untyped-def]
    """Poll `condition` on the event loop until it holds (no fixed sleep: returns at once)."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while not condition():
        if loop.time() > deadline:
            raise TimeoutError("condition not met")
        await asyncio.sleep(0.005)


@pytest.fixture
async def buses():
    config = private_config()
    a, b = Bus.open(config), Bus.open(config)
    yield a, b
    a.close()
    b.close()


async def test_extend_from_a_thread_drops_oldest_and_counts_them() -> None:
    inbox: Inbox[int] = Inbox(asyncio.get_running_loop(), maxsize=5, wakeup_fd=True)
    pusher = threading.Thread(target=inbox.extend, args=(range(12),))
    pusher.start()
    pusher.join()
    assert inbox.dropped == 7
    assert [await inbox.get(1) for _ in range(5)] == [7, 8, 9, 10, 11]
    inbox.close()


@pytest.mark.parametrize("wakeup_fd", [True, False])
async def test_a_parked_consumer_is_woken_by_a_push_from_another_thread(wakeup_fd: bool) -> None:
    inbox: Inbox[str] = Inbox(asyncio.get_running_loop(), maxsize=4, wakeup_fd=wakeup_fd)
    assert (inbox._fd_read >= 0) == wakeup_fd
    consumer = asyncio.ensure_future(inbox.get(timeout=10))
    await wait_until(lambda: inbox._waiter is not None)  # parked on its future
    threading.Thread(target=inbox.push, args=("hello",)).start()
    assert await consumer == "hello"
    # and again after the wake-up was consumed: the eventfd was reset, not left readable
    consumer = asyncio.ensure_future(inbox.get(timeout=10))
    await wait_until(lambda: inbox._waiter is not None)
    threading.Thread(target=inbox.extend, args=(["a", "b"],)).start()
    assert await consumer == "a"
    assert await inbox.get(1) == "b"
    inbox.close()


async def test_close_releases_the_wakeup_descriptor_and_later_pushes_are_harmless() -> None:
    inbox: Inbox[int] = Inbox(asyncio.get_running_loop(), maxsize=4, wakeup_fd=True)
    fd = inbox._fd_read
    os.fstat(fd)
    inbox.close()
    with pytest.raises(OSError):
        os.fstat(fd)
    inbox.push(1)  # a late sample from a drain thread: kept, no write to a closed descriptor
    assert await inbox.get(1) == 1
    with pytest.raises(EOFError):
        await inbox.get(1)


async def test_channel_subscription_keeps_order_and_counts_malformed(buses) -> None:
    a, b = buses
    bad: list[str] = []
    sub = a.subscribe(a.keys.skeleton, s.SkeletonFrame, on_malformed=lambda k, e: bad.append(k))
    pub = b.publisher(b.keys.skeleton, s.SkeletonFrame)
    await pub.wait_matching(timeout=10)
    frames = skeleton_frames(600)
    for i, frame in enumerate(frames):
        pub.put(frame)
        if i % 200 == 0:
            pub.put_bytes(b"\x93garbage")  # skipped and counted, wherever it falls in a burst
    got = [await sub.recv(timeout=10) for _ in frames]
    assert [r.message for r in got] == frames
    assert sub.received == 600
    assert sub.malformed == 3 and bad == [a.keys.skeleton] * 3
    assert sub.dropped == 0


async def test_a_full_subscription_drops_the_oldest_and_counts_them(buses) -> None:
    a, b = buses
    sub = a.subscribe(a.keys.skeleton, s.SkeletonFrame, Delivery(queue=4))
    pub = b.publisher(b.keys.skeleton, s.SkeletonFrame)
    await pub.wait_matching(timeout=10)
    frames = skeleton_frames(40)
    for frame in frames:  # nobody consumes meanwhile
        pub.put(frame)
    await wait_until(lambda: len(sub._inbox) + sub.dropped == 40)
    assert sub.dropped == 36
    assert [(await sub.recv(timeout=5)).message for _ in range(4)] == frames[-4:]


async def test_closing_a_subscription_ends_its_drain_thread(buses) -> None:
    a, _ = buses
    sub = a.subscribe(a.keys.skeleton, s.SkeletonFrame)
    raw = a.subscribe_raw([a.keys.camera, a.keys.objects])

    def drains() -> list[threading.Thread]:
        return [
            t for t in threading.enumerate() if t.name.startswith(f"zenoh-drain {a.keys.root}/")
        ]

    assert len(drains()) == 3
    sub.close()
    raw.close()
    await wait_until(lambda: not drains())
    with pytest.raises(EOFError):
        await sub.recv(timeout=1)


async def test_a_recovering_subscription_delivers_a_burst_in_order(buses) -> None:
    """More than a channel holds, sent while nobody consumes: the history repair sees each
    sample, in order, and hands it on."""
    a, b = buses
    delivery = Delivery(cache=2048, recover=True)  # blocking: a lost sample would be a gap
    sub = a.subscribe(a.keys.skeleton, s.SkeletonFrame, delivery)
    pub = b.publisher(b.keys.skeleton, s.SkeletonFrame, delivery)
    frames = skeleton_frames(700)
    pub.put(frames[0])  # live, or from the cache when the subscriber finds the publisher
    got = [(await sub.recv(timeout=10)).message]
    for frame in frames[1:]:
        pub.put(frame)
    got += [(await sub.recv(timeout=10)).message for _ in frames[1:]]
    assert got == frames
    assert sub.missed == 0 and sub.dropped == 0


@pytest.mark.timeout(60)
async def test_history_larger_than_the_channel_arrives_whole_when_subscribing(buses) -> None:
    """A restarted consumer's history (here 600 samples, more than any channel of Zenoh's
    holds) comes as the subscriber is declared: the declaration returns (a bounded channel
    filled on the declaring thread before anything drains it would block it for ever) and
    every sample arrives once, in order."""
    a, b = buses
    delivery = Delivery(cache=2048, recover=True, history=2048)
    pub = b.publisher(b.keys.skeleton, s.SkeletonFrame, delivery)
    frames = skeleton_frames(600)
    for frame in frames:  # nobody subscribes yet: they wait in the publisher's cache
        pub.put(frame)
    sub = a.subscribe(a.keys.skeleton, s.SkeletonFrame, delivery)
    got = [(await sub.recv(timeout=10)).message for _ in frames]
    assert got == frames
    assert sub.missed == 0 and sub.dropped == 0


async def test_ready_takes_what_has_arrived_without_waiting(buses) -> None:
    a, b = buses
    bad: list[str] = []
    sub = a.subscribe(a.keys.skeleton, s.SkeletonFrame, on_malformed=lambda k, e: bad.append(k))
    assert sub.ready() is None  # nothing yet: None, not a wait
    pub = b.publisher(b.keys.skeleton, s.SkeletonFrame)
    await pub.wait_matching(timeout=10)
    frames = skeleton_frames(5)
    pub.put(frames[0])
    pub.put_bytes(b"\x93garbage")
    for frame in frames[1:]:
        pub.put(frame)
    await wait_until(lambda: sub.pending == 6)
    got = [sub.ready() for _ in frames]
    assert [r.message for r in got if r is not None] == frames
    assert sub.ready() is None and sub.malformed == 1 and bad == [a.keys.skeleton]


async def test_raw_subscription_delivers_bytes_encoding_and_order(buses) -> None:
    a, b = buses
    raw = a.subscribe_raw(a.keys.camera)
    pub = b.publisher(b.keys.camera, s.CameraFrame)
    await pub.wait_matching(timeout=10)
    frames = [camera_frame(i) for i in range(30)]
    for frame in frames:
        pub.put(frame)
    got = [await raw.recv(timeout=5) for _ in frames]
    assert [g.payload for g in got] == [encode(f) for f in frames]
    assert {g.encoding for g in got} == {wire_encoding(s.CameraFrame)}
    assert all(g.received_ns > 0 for g in got)


async def test_put_from_the_owner_and_from_another_thread_sends_the_same_bytes(buses) -> None:
    a, b = buses
    raw = a.subscribe_raw(a.keys.camera)
    pub = b.publisher(b.keys.camera, s.CameraFrame)
    await pub.wait_matching(timeout=10)
    big, small = camera_frame(1, 64, 48), camera_frame(2, 8, 6)
    pub.put(big)
    pub.put(small)  # the reused buffer shrinks: no stale tail from the bigger frame
    await asyncio.to_thread(pub.put, big)  # not the owner thread: its own buffer
    got = [(await raw.recv(timeout=5)).payload for _ in range(3)]
    assert got == [encode(big), encode(small), encode(big)]
    assert pub.sent == 3


def test_encode_into_writes_what_encode_returns() -> None:
    buffer = bytearray(b"stale bytes that must go" * 100)
    for message in (camera_frame(3, 40, 30), skeleton_frames(1)[0], camera_frame(4, 4, 3)):
        encode_into(message, buffer)
        assert bytes(buffer) == encode(message)


async def test_replay_sends_each_recorded_message_as_its_wire_bytes(tmp_path: Path) -> None:
    config = private_config()
    keys = s.Keys(config.robot)
    frames = skeleton_frames(20)
    cams = [camera_frame(i) for i in range(20)]
    path = tmp_path / "mixed.mcap"
    foreign = f"{keys.root}/other/raw"
    with RecordingWriter(path) as writer:
        for frame, cam in zip(frames, cams, strict=True):
            writer.write(keys.skeleton, frame)
            writer.write(keys.camera, cam)
        # a key that is not ours, stored as it came
        writer.write_wire(foreign, b"\x00opaque", "text/plain", frames[-1].header.stamp + 5)
    with Bus.open(config) as bus, Bus.open(config) as listener:
        raw = listener.subscribe_raw(keys.everything)
        probe = bus.publisher(keys.skeleton, s.SkeletonFrame)
        await probe.wait_matching(timeout=10)
        probe.close()
        stats = await replay(bus, path, rate=None)
        got, ticks = [], 0
        while len(got) < 41:
            sample = await raw.recv(timeout=5)
            if sample.key == keys.clock:  # the replay's stream clock, beside what it replays
                ticks += 1
            else:
                got.append(sample)
    assert stats.messages == 41 and ticks > 0
    by_key: dict[str, list[bytes]] = {}
    for sample in got:
        by_key.setdefault(sample.key, []).append(sample.payload)
    assert by_key[keys.skeleton] == [encode(f) for f in frames]
    assert by_key[keys.camera] == [encode(c) for c in cams]
    assert by_key[foreign] == [b"\x00opaque"]
    encodings = {sample.key: sample.encoding for sample in got}
    assert encodings[keys.camera] == wire_encoding(s.CameraFrame)
    assert encodings[foreign] == "text/plain"


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_chunk_parser_reads_what_mcap_reads(tmp_path: Path, compression: str) -> None:
    from mcap.reader import make_reader

    from beyond_self.runtime.recording.reader import read_recording

    keys = s.Keys("robot")
    path = tmp_path / f"{compression}.mcap"
    frames = skeleton_frames(30)
    cams = [camera_frame(i, 64, 48) for i in range(30)]
    with RecordingWriter(path, compression=compression, chunk_size=16 * 1024) as writer:
        for frame, cam in zip(frames, cams, strict=True):
            writer.write(keys.skeleton, frame)
            writer.write(keys.camera, cam)
    ours = [(r.key, r.log_time, r.publish_time, r.data) for r in read_recording(path)]
    with open(path, "rb") as f:  # mcap's own reader, no project code
        theirs = [
            (channel.topic, m.log_time, m.publish_time, m.data)
            for _, channel, m in make_reader(f).iter_messages(log_time_order=False)
        ]
    assert len(ours) == 60
    assert sorted(ours) == sorted(theirs)
    assert [r.message() for r in read_recording(path, topics=[keys.camera])] == cams


def test_a_corrupt_chunk_is_reported_as_damage(tmp_path: Path) -> None:
    from beyond_self.core.errors import InputError
    from beyond_self.runtime.recording.reader import read_recording

    keys = s.Keys("robot")
    path = tmp_path / "corrupt.mcap"
    with RecordingWriter(path, compression="none", chunk_size=4 * 1024) as writer:
        for frame in skeleton_frames(40):
            writer.write(keys.skeleton, frame)
    raw = bytearray(path.read_bytes())
    at = raw.index(b'"hand_right"', len(raw) // 2)  # inside a chunk in the second half
    raw[at + 1] ^= 0x20
    path.write_bytes(bytes(raw))
    damage: list[str] = []
    got = list(read_recording(path, on_damage=lambda info: damage.append(info.error)))
    assert 0 < len(got) < 40
    assert damage and "CRC" in damage[0].upper()
    # a damaged chunk costs only itself: the last frame, after it, is still read
    assert got[-1].message() == skeleton_frames(40)[-1]
    assert f"played the other {len(got)}" in damage[0]
    with pytest.raises(InputError, match="is damaged: unreadable: chunk at byte"):
        list(read_recording(path))


async def test_large_frames_come_out_as_bytes_and_intact(buses) -> None:
    """Frames above Zenoh's batch size stay in Zenoh's buffer until the loop takes them."""
    a, b = buses
    typed = a.subscribe(a.keys.camera, s.CameraFrame)
    raw = a.subscribe_raw(a.keys.camera)
    pub = b.publisher(b.keys.camera, s.CameraFrame)
    await pub.wait_matching(timeout=10)
    frames = [camera_frame(i, 320, 240) for i in range(5)]
    assert len(encode(frames[0])) > 200_000
    for frame in frames:
        pub.put(frame)
    got = [await typed.recv(timeout=10) for _ in frames]
    assert [r.message for r in got] == frames
    samples = [await raw.recv(timeout=10) for _ in frames]
    assert all(type(x.payload) is bytes for x in samples)
    assert [x.payload for x in samples] == [encode(f) for f in frames]


async def test_get_with_a_timeout_wakes_on_a_push_and_leaves_no_stale_waiter() -> None:
    inbox: Inbox[int] = Inbox(asyncio.get_running_loop(), maxsize=4, wakeup_fd=True)
    consumer = asyncio.ensure_future(inbox.get(timeout=10))
    await wait_until(lambda: inbox._waiter is not None)
    threading.Thread(target=inbox.push, args=(5,)).start()
    assert await consumer == 5
    with pytest.raises(TimeoutError):
        await inbox.get(timeout=0.01)
    assert inbox._waiter is None
    cancelled = asyncio.ensure_future(inbox.get(timeout=10))
    await wait_until(lambda: inbox._waiter is not None)
    cancelled.cancel()
    with pytest.raises(asyncio.CancelledError):
        await cancelled
    assert inbox._waiter is None
    inbox.push(6)  # nobody parked: no wake-up is sent, the item waits
    assert not inbox._wake_pending
    assert await inbox.get(timeout=1) == 6
    inbox.close()
