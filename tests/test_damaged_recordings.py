"""One policy for damaged recordings (issue 21): `inspect`, `analyse` and `up` agree.

The family is made here from the shortest shipped recording: truncated at 50% and 90%, bytes of
a chunk flipped, an empty file, a file that is no MCAP, a NaN joint, stamps going backwards and
stamps repeated. For each, the three commands exit with the same status (2: something was lost,
or nothing is readable), print no traceback, say what was lost in one line (the same line), and
`analyse` and `up` print the same gesture lines: what is readable is played.
"""

from __future__ import annotations

import asyncio
import json
import re
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from busutil_net import env_for, private_config, skeleton_frames
from mcap.reader import make_reader
from mcap.writer import Writer

from beyond_self.runtime.recording.damage import Losses
from beyond_self.runtime.recording.reader import inspect_recording, scan_recording
from beyond_self.runtime.recording.scan import Walk, mapped
from beyond_self.services.launcher import BEYOND

SOURCE = Path(__file__).resolve().parent.parent / "recordings" / "touch-box.mcap"
Change = Callable[[int, str, bytes, int], Iterator[tuple[bytes, int]]]


def rewritten(src: Path, dst: Path, change: Change) -> Path:
    """`src` written again message by message (our channels and schemas, as another MCAP
    writer would), each message passed through `change(index, topic, data, stamp)`."""
    with open(src, "rb") as f, open(dst, "wb") as out:
        writer = Writer(out)
        writer.start(profile="", library="test")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for i, (schema, channel, msg) in enumerate(
            make_reader(f).iter_messages(log_time_order=False)
        ):
            assert schema is not None
            if schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(
                    schema.name, schema.encoding, schema.data
                )
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schemas[schema.id], channel.metadata
                )
            for data, stamp in change(i, channel.topic, msg.data, msg.publish_time):
                writer.add_message(channels[channel.id], stamp, data, stamp)
        writer.finish()
    return dst


def skeleton_at(n: int, change: Callable[[bytes, int], Iterator[tuple[bytes, int]]]) -> Change:
    """Apply `change` to the n-th skeleton frame only."""
    seen = [0]

    def apply(_i: int, topic: str, data: bytes, stamp: int) -> Iterator[tuple[bytes, int]]:
        if topic.endswith("/skeleton"):
            seen[0] += 1
            if seen[0] == n:
                yield from change(data, stamp)
                return
        yield data, stamp

    return apply


def nan_joint(data: bytes, stamp: int) -> Iterator[tuple[bytes, int]]:
    frame = json.loads(data)
    frame["joints"]["right_hand"]["position"][0] = float("nan")
    yield json.dumps(frame).encode(), stamp


def backwards(data: bytes, stamp: int) -> Iterator[tuple[bytes, int]]:
    frame = json.loads(data)
    back = stamp - 3_000_000_000  # past the readers' 2 s reordering window
    frame["header"]["stamp"] = {"sec": back // 10**9, "nsec": back % 10**9}
    yield json.dumps(frame).encode(), back


def repeated(data: bytes, stamp: int) -> Iterator[tuple[bytes, int]]:
    yield data, stamp
    yield data, stamp


def family(folder: Path) -> dict[str, Path]:
    data = SOURCE.read_bytes()
    with open(SOURCE, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and len(summary.chunk_indexes) >= 3
    chunk = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)[1]
    flipped = bytearray(data)
    middle = chunk.chunk_start_offset + chunk.chunk_length // 2
    flipped[middle : middle + 16] = bytes(b ^ 0xFF for b in flipped[middle : middle + 16])
    files = {
        "truncated-50": data[: len(data) // 2],
        "truncated-90": data[: len(data) * 9 // 10],
        "chunk-flipped": bytes(flipped),
        "empty": b"",
        "not-mcap": b"frame,x,y,z\n1,0.1,0.2,0.3\n" * 100,
    }
    out = {}
    for name, content in files.items():
        out[name] = folder / f"{name}.mcap"
        out[name].write_bytes(content)
    for name, change in (
        ("nan-joint", skeleton_at(60, nan_joint)),
        ("backward-stamp", skeleton_at(100, backwards)),  # 3.3 s in: sent back to 0.3 s
        ("repeated-stamp", skeleton_at(60, repeated)),
    ):
        out[name] = rewritten(SOURCE, folder / f"{name}.mcap", change)
    return out


async def run(args: list[str], env: dict[str, str], cwd: Path) -> tuple[int, str, str]:
    proc = await asyncio.create_subprocess_exec(
        *BEYOND, *args, env=env, cwd=cwd, stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    out, err = await asyncio.wait_for(proc.communicate(), 240)
    assert proc.returncode is not None
    return proc.returncode, out.decode(), err.decode()


def gesture_lines(stdout: str) -> list[str]:
    return [line for line in stdout.splitlines() if re.match(r"gesture \d+: ", line)]


def error_line(command: str, stderr: str) -> str:
    """The one line the command said about the damage (what follows its error prefix)."""
    said = [line for line in stderr.splitlines() if line.startswith(f"beyond {command}: error: ")]
    assert len(said) == 1, stderr[-3000:]
    return said[0].split(": error: ", 1)[1]


@pytest.mark.slow
@pytest.mark.timeout(600)
async def test_inspect_analyse_and_up_agree_on_every_damaged_recording(
    tmp_path: Path, show: Callable[[str], None]
) -> None:
    files = family(tmp_path)
    results: dict[str, dict[str, Any]] = {}
    running = asyncio.Semaphore(3)  # `up` starts six processes: three at a time

    async def check(name: str, path: Path) -> None:
        env = {**env_for(private_config()), "BEYOND_LOG_FORMAT": "text"}
        async with running:
            got = await asyncio.gather(
                run(["inspect", str(path)], env, tmp_path),
                run(["analyse", str(path)], env, tmp_path),
                run(["up", "--recording", str(path), "--rate", "0", "--no-live"], env, tmp_path),
            )
        results[name] = dict(zip(("inspect", "analyse", "up"), got, strict=True))

    await asyncio.gather(*(check(name, path) for name, path in files.items()))
    table = []
    for name, by_command in results.items():
        codes = {command: r[0] for command, r in by_command.items()}
        assert set(codes.values()) == {2}, (name, codes)  # something lost: exit 2, all three
        for command, (_, _, err) in by_command.items():
            assert "Traceback" not in err, (name, command, err[-3000:])
        lines = {command: error_line(command, r[2]) for command, r in by_command.items()}
        assert len(set(lines.values())) == 1, (name, lines)  # the same one line
        line = lines["up"]
        up_err = by_command["up"][2]
        assert sum(line in said for said in up_err.splitlines()) == 1, up_err[-3000:]
        analysed = gesture_lines(by_command["analyse"][1])
        assert gesture_lines(by_command["up"][1]) == analysed, name  # same gestures told
        table.append(f"{name}: exit 2, {len(analysed)} gesture lines: {line}")
    for name in ("nan-joint", "backward-stamp", "repeated-stamp"):
        # one bad frame costs only itself: the gesture is told (a flipped chunk of this short
        # recording holds its gesture; test_a_damaged_chunk_costs_only_itself reads past one)
        assert any(line.endswith('"') for line in gesture_lines(results[name]["up"][1])), name
    show("damaged recordings:\n" + "\n".join(table))


def test_a_damaged_chunk_costs_only_itself(tmp_path: Path) -> None:
    """A flipped bit in one chunk of many: the chunks after it are read (they used to be
    hidden), and the line says what was lost, also with the summary gone."""
    from beyond_self.runtime.recording.writer import RecordingWriter

    path = tmp_path / "many.mcap"
    frames = skeleton_frames(90)
    with RecordingWriter(path, compression="zstd", chunk_size=1024) as writer:
        for frame in frames:
            writer.write("beyond/r/sensors/skeleton", frame)
    data = bytearray(path.read_bytes())
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    assert len(chunks) >= 9
    second = chunks[1]
    data[second.chunk_start_offset + second.chunk_length - 20] ^= 0x01
    for name, content in (("flipped", bytes(data)), ("no-summary", bytes(data[:-600]))):
        damaged = tmp_path / f"{name}.mcap"
        damaged.write_bytes(content)
        info = inspect_recording(damaged)
        scanned = scan_recording(damaged)  # what a player reads before it plays: the same
        assert (scanned.start, scanned.end, scanned.messages, scanned.channels) == (
            info.start, info.end, info.messages, info.channels)  # fmt: skip
        lost = len(frames) - info.messages
        assert 0 < lost < len(frames) // 4, (name, info.messages)  # one chunk, not the rest
        assert info.end is not None and info.end >= frames[-2].header.stamp  # read to the end
        assert f"chunk at byte {second.chunk_start_offset}" in info.error, info.error
    # a damaged record header: skipped to the next chunk, the skipped bytes said
    header = bytearray(path.read_bytes())
    header[chunks[3].chunk_start_offset] = 0x77  # no such record type
    (tmp_path / "header.mcap").write_bytes(bytes(header))
    info = inspect_recording(tmp_path / "header.mcap")
    assert f"bytes {chunks[3].chunk_start_offset}-" in info.error
    assert info.end is not None and info.end >= frames[-2].header.stamp
    with mapped(tmp_path / "header.mcap") as raw:
        walk = Walk(raw, Losses("x"))
        assert walk.next_chunk(chunks[3].chunk_start_offset + 1) == chunks[4].chunk_start_offset
