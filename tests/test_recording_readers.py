"""Recordings read by programs nobody here wrote: @mcap/core (Foxglove's reader, in Node.js) with
CRC checks, and `pymcap-cli doctor`. A JavaScript reader parses JSON numbers as doubles, so this
also checks that every stamp it sees equals the message's log time exactly."""

from __future__ import annotations

import asyncio
import subprocess
from pathlib import Path

import pytest
from busutil_net import REPO, env_for, private_config
from third_party_readers import assert_trusted, js_reports

import beyond_self.schemas as s
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.clock import ClockTicks
from beyond_self.runtime.recording.reader import inspect_recording, read_recording
from beyond_self.runtime.recording.replay import replay
from beyond_self.services.launcher import BEYOND

SHIPPED = sorted((REPO / "recordings").glob("*.mcap"))


@pytest.mark.parametrize("path", SHIPPED, ids=[p.name for p in SHIPPED])
def test_shipped_recordings_read_exactly_in_javascript(node_modules: Path, path: Path) -> None:
    (report,) = js_reports(node_modules, [path])
    assert report["unstamped"] == 0
    assert_trusted(report, path)


def write_form1(path: Path, messages: list[s.Message], key: str) -> None:
    """A file as this project wrote it before recordings had a JSON form: stamps as integers,
    no form in the channel metadata, no data-section CRC."""
    from mcap.writer import Writer

    with open(path, "wb") as f:
        writer = Writer(f)
        writer.start(profile="", library="beyond-self 0.1.0 (form 1)")
        cls = type(messages[0])
        schema = writer.register_schema(cls.schema_name(), "jsonschema", s.json_schema_bytes(cls))
        channel = writer.register_channel(
            key, "json", schema, {"beyond.type": cls.type_name(), "beyond.version": "1"}
        )
        for m in messages:
            stamp = m.header.stamp
            writer.add_message(channel, stamp, s.to_json(m), stamp)
        writer.finish()


def test_older_recording_reads_here_and_is_what_javascript_rounds(
    node_modules: Path, tmp_path: Path
) -> None:
    """The checker can fail: a file in the old form is caught; this build still reads it."""
    new = REPO / "recordings" / "touch-box.mcap"
    skeletons = [r.message() for r in read_recording(new, topics=["beyond/*/sensors/skeleton"])]
    old = tmp_path / "old.mcap"
    write_form1(old, skeletons, "beyond/robot/sensors/skeleton")
    assert [r.message() for r in read_recording(old)] == skeletons
    (report,) = js_reports(node_modules, [old])
    assert report["messages"] == len(skeletons)
    assert 0 < report["stamp_mismatch"]["beyond/robot/sensors/skeleton"] < len(skeletons)
    assert not report["data_section_crc_ok"]


async def test_beyond_record_file_is_trusted(node_modules: Path, tmp_path: Path) -> None:
    """`beyond record --foxglove` during a replay, plus what a live bus also carries: an unstamped
    message (a service whose recording clock has not started) and a sample that is not ours."""
    config = private_config()
    out = tmp_path / "recorded.mcap"
    source = REPO / "recordings" / "touch-box.mcap"
    ticks: list[int] = []  # the replay's stream clock, which it publishes as it plays
    clock = ClockTicks(ticks.append)
    for item in read_recording(source):
        clock.at(item.publish_time)
    clock.last(item.publish_time)
    expected = inspect_recording(source).messages + len(ticks) + 2
    with Bus.open(config) as bus:
        proc = subprocess.Popen(
            [
                *(*BEYOND, "record", "--foxglove"),
                *("-o", str(out), "--count", str(expected)),
            ],
            env=env_for(config),
            stderr=subprocess.PIPE,
            text=True,
        )
        try:
            probe = bus.publisher(bus.keys.stream_end, s.StreamEnd)
            await probe.wait_matching(timeout=30)
            await replay(bus, source, rate=None, robot=config.robot)
            header = s.Header(version=s.StreamEnd.VERSION, source="t", seq=0, stamp=0)
            probe.put(s.StreamEnd(header=header, source="t", messages=0))
            raw = bus.raw_publisher(f"{bus.keys.root}/custom/text", "text/plain")
            raw.put(b"not ours")
            rc = await asyncio.to_thread(proc.wait, 60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    assert rc == 0, proc.stderr.read() if proc.stderr else ""
    items = list(read_recording(out))
    assert len(items) == expected
    stamps = [r.publish_time for r in items if r.key.endswith("sensors/skeleton")]
    unstamped = [r for r in items if r.key.endswith("sensors/end")]
    assert len(unstamped) == 1 and unstamped[0].message().header.stamp == 0
    # logged on the stamps' clock (after the replayed data), not at 0 nor at today's wall time
    assert unstamped[0].log_time == unstamped[0].publish_time >= max(stamps)
    assert unstamped[0].log_time < max(stamps) + 60 * 10**9
    clocks = [r.message().header.stamp for r in items if r.key.endswith("/clock")]
    assert clocks == ticks and clocks[0] == min(stamps) and clocks[-1] == max(stamps)
    # the Foxglove views went in too, one scene per skeleton frame, and replay skips them
    counts = {c.topic: c.count for c in inspect_recording(out).channels}
    assert counts[f"beyond/{config.robot}/foxglove/scene"] == len(stamps) > 0
    assert not [r for r in items if "/foxglove/" in r.key]
    (report,) = js_reports(node_modules, [out])
    assert report["unstamped"] == 1 and report["unchecked"] == 0
    assert_trusted(report, out)


def test_export_adds_foxglove_views_to_a_shipped_recording(
    node_modules: Path, tmp_path: Path
) -> None:
    source = REPO / "recordings" / "touch-box.mcap"
    out = tmp_path / "touch-views.mcap"
    done = subprocess.run(
        [
            *BEYOND,
            "foxglove",
            "--export",
            str(source),
            "-o",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    counts = {c.topic: c.count for c in inspect_recording(out).channels}
    assert counts["beyond/robot/foxglove/scene"] == counts["beyond/robot/sensors/skeleton"] > 0
    recorded = {c.topic for c in inspect_recording(source).channels}
    assert [r.message() for r in read_recording(out) if r.key in recorded] == [
        r.message() for r in read_recording(source)
    ]
    assert inspect_recording(out).metadata == inspect_recording(source).metadata
    (report,) = js_reports(node_modules, [out])
    assert report["unchecked"] == 0
    assert_trusted(report, out)
    again = subprocess.run(
        [
            *BEYOND,
            "foxglove",
            "--export",
            str(out),
            "-o",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert again.returncode == 2 and "overwrite its input" in again.stderr
