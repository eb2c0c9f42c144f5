"""MCAP recordings: self-describing, deterministic, crash-safe, replayable."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest
from busutil_net import env_for, private_config, skeleton_frames
from mcap.reader import make_reader
from third_party_readers import doctor

import beyond_self.schemas as s
from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.recording.reader import (
    inspect_recording,
    read_recording,
    scan_recording,
)
from beyond_self.runtime.recording.replay import replay
from beyond_self.runtime.recording.writer import RecordingWriter
from beyond_self.services.launcher import BEYOND

ROBOT_KEYS = s.Keys("r1")
SHIPPED = sorted((Path(__file__).resolve().parent.parent / "recordings").glob("*.mcap"))


def camera(i: int, stamp: int) -> s.CameraFrame:
    h = s.Header(version=1, source="cam", seq=i, stamp=stamp)
    pixels = bytes((x * 7 + i) % 256 for x in range(8 * 6 * 3))
    return s.CameraFrame.build(h, 8, 6, pixels)


def write_sample(path: Path, n: int = 90, chunk_size: int = 2048) -> list[tuple[str, s.Message]]:
    written: list[tuple[str, s.Message]] = []
    with RecordingWriter(path, chunk_size=chunk_size) as w:
        for f in skeleton_frames(n):
            w.write(ROBOT_KEYS.skeleton, f)
            written.append((ROBOT_KEYS.skeleton, f))
            if f.frame % 3 == 0:
                c = camera(f.frame, f.header.stamp + 1)
                w.write(ROBOT_KEYS.camera, c)
                written.append((ROBOT_KEYS.camera, c))
    return written


def test_same_messages_same_bytes(tmp_path: Path) -> None:
    write_sample(tmp_path / "a.mcap")
    write_sample(tmp_path / "b.mcap")
    a, b = (tmp_path / "a.mcap").read_bytes(), (tmp_path / "b.mcap").read_bytes()
    assert a == b and len(a) > 1000


def test_standard_mcap_reader_decodes_without_project_code(tmp_path: Path) -> None:
    path = tmp_path / "r.mcap"
    written = write_sample(path)
    with open(path, "rb") as f:
        reader = make_reader(f)
        rows = list(reader.iter_messages(log_time_order=False))
        summary = reader.get_summary()
    assert summary is not None and summary.statistics.message_count == len(written)
    assert len(rows) == len(written)
    for (schema, channel, message), (key, original) in zip(rows, written, strict=True):
        assert channel.topic == key
        assert channel.message_encoding == "json"
        assert schema.encoding == "jsonschema"
        json.loads(schema.data)  # a valid JSON Schema document
        data = json.loads(message.data)
        assert message.publish_time == original.header.stamp
        stamp = data["header"]["stamp"]  # a Foxglove Time: exact for any JSON reader
        assert stamp["sec"] * 10**9 + stamp["nsec"] == original.header.stamp
        assert message.log_time == original.header.stamp
        if isinstance(original, s.CameraFrame):
            assert schema.name == "foxglove.RawImage"
            assert (data["width"], data["height"], data["encoding"]) == (8, 6, "rgb8")
            assert base64.b64decode(data["data"]) == original.data
            ts = data["timestamp"]
            assert ts["sec"] * 10**9 + ts["nsec"] == original.header.stamp
        else:
            assert schema.name == "beyond.SkeletonFrame"
            assert data["joints"]["hand_right"]["position"] == list(
                original.joints["hand_right"].position
            )


def test_read_back_in_stamp_order_with_filters(tmp_path: Path) -> None:
    path = tmp_path / "r.mcap"
    written = write_sample(path)
    got = list(read_recording(path))
    assert [r.message() for r in got] == [m for _, m in written]
    stamps = [r.publish_time for r in got]
    assert stamps == sorted(stamps)
    cams = list(read_recording(path, topics=["beyond/*/sensors/camera/**"]))
    assert len(cams) == 30 and all(r.cls is s.CameraFrame for r in cams)
    window = [
        r.message() for r in read_recording(path, topics=[ROBOT_KEYS.skeleton], start=1.0, end=2.0)
    ]
    period = int(1e9 / 30)  # the synthetic frames' spacing
    expected = [i for i in range(90) if 1.0 <= i * period / 1e9 <= 2.0]
    assert [f.frame for f in window] == expected and len(expected) == 30
    payload, encoding = got[0].wire()
    assert s.decode(payload, s.SkeletonFrame) == written[0][1]
    assert s.type_from_encoding(encoding) is s.SkeletonFrame


def test_inspect_counts_channels_and_duration(tmp_path: Path) -> None:
    path = tmp_path / "r.mcap"
    write_sample(path)
    info = inspect_recording(path)
    assert info.complete and not info.error
    assert info.messages == 120
    counts = {c.topic: (c.count, c.schema_name) for c in info.channels}
    assert counts == {
        ROBOT_KEYS.skeleton: (90, "beyond.SkeletonFrame"),
        ROBOT_KEYS.camera: (30, "foxglove.RawImage"),
    }
    assert info.duration_s == pytest.approx(89 / 30, abs=1e-3)


def test_truncated_file_reports_what_is_readable(tmp_path: Path) -> None:
    path = tmp_path / "r.mcap"
    write_sample(path, n=60, chunk_size=1)  # one message per chunk
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    ends = sorted(ci.chunk_start_offset + ci.chunk_length for ci in summary.chunk_indexes)
    data = path.read_bytes()
    for cut in (ends[10] + 5, ends[41], len(data) // 2, 30):
        cut_path = tmp_path / f"cut{cut}.mcap"
        cut_path.write_bytes(data[:cut])
        expected = sum(1 for end in ends if end <= cut)
        info = inspect_recording(cut_path)
        assert not info.complete and info.error
        assert info.messages == expected
        line = info.damage()
        assert f"of {cut}" in line and f"played the other {expected}" in line
        result = subprocess.run(
            [*BEYOND, "inspect", str(cut_path)],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert result.returncode == 2
        errors = result.stderr.strip().splitlines()
        assert len(errors) == 1 and "is damaged: truncated at byte" in errors[0]
        assert f"played the other {expected}" in errors[0]


def test_corrupt_chunk_is_detected(tmp_path: Path) -> None:
    path = tmp_path / "r.mcap"
    write_sample(path, n=30, chunk_size=1)
    data = bytearray(path.read_bytes())
    data[len(data) // 3] ^= 0xFF
    path.write_bytes(bytes(data))
    info = inspect_recording(path)
    assert info.error and info.messages < 40


async def test_killed_recorder_leaves_readable_file(tmp_path: Path) -> None:
    config = private_config()
    out = tmp_path / "killed.mcap"
    frames = skeleton_frames(40)
    with Bus.open(config) as bus:
        proc = subprocess.Popen(
            [
                *BEYOND,
                "record",
                bus.keys.everything,
                "-o",
                str(out),
                "--flush-interval",
                "0.1",
            ],
            env=env_for(config),
            stderr=subprocess.DEVNULL,
        )
        try:
            pub = bus.publisher(bus.keys.skeleton, s.SkeletonFrame)
            await pub.wait_matching(timeout=20)
            for f in frames:
                pub.put(f)
            deadline = time.monotonic() + 20
            while time.monotonic() < deadline:  # wait for the chunks to reach the file
                with contextlib.suppress(InputError):  # not written yet, or only its start
                    if inspect_recording(out).messages == len(frames):
                        break
                await asyncio.sleep(0.05)
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)
        finally:
            if proc.poll() is None:
                proc.kill()
    info = inspect_recording(out)
    assert not info.complete  # no summary or footer: it really died mid-recording
    assert info.messages == len(frames)
    damaged = []
    got = [r.message() for r in read_recording(out, on_damage=damaged.append)]
    assert got == frames and len(damaged) == 1
    # logged at the sender's stamp, so a viewer's timeline and the message agree
    assert all(
        r.log_time == r.publish_time == r.message().header.stamp
        for r in read_recording(out, on_damage=print)
    )


async def test_replay_timing_filters_and_robot_rename(tmp_path: Path) -> None:
    path = tmp_path / "r.mcap"
    write_sample(path, n=31)  # 1.0 s of skeleton at 30 Hz
    config = private_config()
    with Bus.open(config) as bus, Bus.open(config) as listener:
        sub = listener.subscribe(listener.keys.skeleton, s.SkeletonFrame)
        cams = listener.subscribe(listener.keys.camera, s.CameraFrame)
        probe = bus.publisher(bus.keys.skeleton, s.SkeletonFrame)
        await probe.wait_matching(timeout=10)
        stats = await replay(
            bus, path, rate=4.0, robot=config.robot, topics=["beyond/*/sensors/skeleton"]
        )
        assert stats.messages == 31
        assert stats.wall_s >= 0.2  # paced: 1 s of recording at 4x (how fast: bench/bus.py)
        got = [(await sub.recv(timeout=5)).message for _ in range(31)]
        assert [f.frame for f in got] == list(range(31))
        assert len(cams._inbox) == 0  # filtered out
        fast = await replay(bus, path, rate=None, robot=config.robot)
        assert fast.messages == 42  # unpaced; its speed is measured in bench/bus.py, not here
        assert [(await cams.recv(timeout=5)).message.header.seq for _ in range(11)] == list(
            range(0, 31, 3)
        )


def test_a_live_recording_has_one_timeline(tmp_path: Path) -> None:
    """What `beyond record` writes from the wire: a message stamped 0 before any stamp (progress
    or health of a service waiting for a replay) waits and is logged at the stream's first
    instant; an output that arrives after newer inputs is written in log-time order within its
    chunk; one stamped 0 later goes on its channel, never before that channel's last message."""
    path = tmp_path / "live.mcap"
    wall = 1_796_000_000 * 10**9  # arrival times: today's wall clock, years after the stream's

    def progress(stamp: int) -> bytes:  # a service's report, stamped by its clock
        header = s.Header(version=1, source="x", seq=0, stamp=stamp)
        return s.encode(s.Progress(header=header, service="x", handled={}))

    frames = skeleton_frames(3)
    stamps = [f.header.stamp for f in frames]
    report, skeleton = ROBOT_KEYS.progress("x"), ROBOT_KEYS.skeleton
    enc = s.wire_encoding
    with RecordingWriter(path, flush_interval=3600.0) as w:
        w.write_wire(report, progress(0), enc(s.Progress), wall)  # before the stream
        for i in (1, 2, 0):  # frame 0 arrives last (a late output), same chunk
            w.write_wire(skeleton, s.encode(frames[i]), enc(s.SkeletonFrame), wall + 10 + i)
        w.write_wire(report, progress(stamps[2] + 5), enc(s.Progress), wall + 20)
        w.write_wire(report, progress(0), enc(s.Progress), wall + 15)  # arrival < last
    logged = [(r.key, r.log_time) for r in read_recording(path)]
    reported = [t for k, t in logged if k == report]  # the first stamp seen, then on
    assert reported == [stamps[1], stamps[2] + 5, stamps[2] + 5]
    assert max(t for _, t in logged) - min(t for _, t in logged) < 10**9  # no wall time
    with open(path, "rb") as f:  # as written, chunk by chunk: never back in time
        written = [m.log_time for _, _, m in make_reader(f).iter_messages(log_time_order=False)]
    assert written == sorted(written) and len(written) == 6


def test_a_channels_log_times_never_step_back(tmp_path: Path) -> None:
    """A gesture's final belief, stamped at the gesture's end, reaches the recorder after the
    beliefs of later frames: within a flush interval it is written in its place (log time =
    its stamp); later than the flushes wait for, at its channel's last log time (ROS and
    Foxglove players assume a channel's log times never step back), its stamp, publish time
    and contents its own. Either way it is read back in stamp order."""
    frames = skeleton_frames(6)
    stamps = [f.header.stamp for f in frames]
    key, enc = ROBOT_KEYS.skeleton, s.wire_encoding(s.SkeletonFrame)
    for flushes, late_log in ((1, stamps[4]), (2, stamps[5])):
        path = tmp_path / f"late{flushes}.mcap"
        with RecordingWriter(path, flush_interval=3600.0) as w:
            for i in (0, 1, 2, 3, 5, 4):  # 4 comes after 5
                if i == 4:
                    for _ in range(flushes):  # idle flushes (the recorder's, each interval)
                        w.flush()
                w.write_wire(key, s.encode(frames[i]), enc, 0)
        with open(path, "rb") as f:
            written = {m.publish_time: m.log_time for _, _, m in make_reader(f).iter_messages(
                log_time_order=False)}  # fmt: skip
        logs = list(written.values())
        assert logs == sorted(logs), flushes
        assert written[stamps[4]] == late_log, flushes
        assert all(written[stamps[i]] == stamps[i] for i in (0, 1, 2, 3, 5))
        assert [r.message() for r in read_recording(path)] == frames


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_a_scan_finds_what_inspect_finds_without_decoding(path: Path) -> None:
    """A player (`beyond replay`, the ingest) reads a recording's channels and span with
    `scan_recording` before it plays, and decodes each message once, as it sends it."""
    info, scanned = inspect_recording(path), scan_recording(path)
    assert scanned.messages == info.messages > 0
    assert (scanned.start, scanned.end, scanned.channels) == (info.start, info.end, info.channels)
    assert scanned.metadata == info.metadata and not scanned.losses.any


def test_a_late_message_never_puts_a_chunk_back_in_time(tmp_path: Path) -> None:
    """A frame later than the flushes wait for is logged at its channel's last time; a message of
    another channel stamped between the two, written in the same flush, follows it, so the
    chunk's log times never step back (`mcap doctor` reads a chunk in order)."""
    frames = skeleton_frames(6)
    stamps = [f.header.stamp for f in frames]
    skeleton, report = ROBOT_KEYS.skeleton, ROBOT_KEYS.progress("x")
    path = tmp_path / "late.mcap"
    with RecordingWriter(path, flush_interval=3600.0) as w:
        for i in (0, 1, 2, 3, 5):
            w.write_wire(skeleton, s.encode(frames[i]), s.wire_encoding(s.SkeletonFrame), 0)
        w.flush()
        w.flush()  # frame 5 is written; frame 4 comes later than the flushes wait for
        w.write_wire(skeleton, s.encode(frames[4]), s.wire_encoding(s.SkeletonFrame), 0)
        header = s.Header(version=1, source="x", seq=0, stamp=stamps[4] + 1)
        between = s.Progress(header=header, service="x", handled={})
        w.write_wire(report, s.encode(between), s.wire_encoding(s.Progress), 0)
    with open(path, "rb") as f:
        written = [(c.topic, m.log_time) for _, c, m in make_reader(f).iter_messages(
            log_time_order=False)]  # fmt: skip
    assert written[-2:] == [(report, stamps[4] + 1), (skeleton, stamps[5])]  # one chunk, in order
    codes = [f["code"] for f in doctor(path)["findings"]]
    assert "NON_MONOTONIC_LOG_TIME" not in codes, codes
