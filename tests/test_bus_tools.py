"""The ros2-topic-style tools: `beyond hz`, `bw`, `info`, `pub`, `schemas export`, and replay's
remap and pause. CLI runs are real subprocesses on a private bus; each waits on what it prints
(or on messages), never on a fixed delay."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import jsonschema
import msgspec
import pytest
from busutil_net import REPO, env_for, private_config, skeleton_frames

import beyond_self.schemas as s
from beyond_self.runtime.bus.delivery import Delivery
from beyond_self.runtime.bus.rates import RateWindow
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.recording.reader import read_recording
from beyond_self.runtime.recording.replay import replay
from beyond_self.runtime.recording.replay_control import ReplayControl, remapper
from beyond_self.runtime.service import Service
from beyond_self.schemas.codec import recording_json_schema, to_recording_json
from beyond_self.services.launcher import BEYOND

DEMO = REPO / "recordings" / "tap-ball-grasp-box.mcap"


async def beyond(config, *args: str) -> asyncio.subprocess.Process:
    return await asyncio.create_subprocess_exec(
        *BEYOND,
        *args,
        env=env_for(config),
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )


async def wait_line(stream: asyncio.StreamReader, prefix: str, timeout: float = 60) -> str:
    async def find() -> str:
        while line := (await stream.readline()).decode():
            if line.startswith(prefix):
                return line
        raise AssertionError(f"stream ended before a line starting {prefix!r}")

    return await asyncio.wait_for(find(), timeout)


def run_cli(config, *args: str) -> tuple[int, str, str]:
    import subprocess

    done = subprocess.run(
        [*BEYOND, *args],
        env=env_for(config),
        capture_output=True,
        text=True,
        timeout=60,
    )
    return done.returncode, done.stdout, done.stderr


def test_rate_is_per_stream_span_not_listening_time() -> None:
    """A 30 Hz stream that starts 0.8 s into a 2 s listen is 30 Hz (the old topics said 18)."""
    window = RateWindow(None)
    start, period = 10**18 + 800_000_000, 10**9 // 30
    for i in range(36):  # 1.2 s of frames
        window.add(start + i * period, 100, stamp_ns=5 * 10**17 + i * period)
    stats = window.stats()
    assert stats.arrival_hz == pytest.approx(30, rel=1e-3)
    assert stats.stamp_hz == pytest.approx(30, rel=1e-3)
    assert stats.bytes_per_s == pytest.approx(3000, rel=1e-3)
    sliding = RateWindow(0.5)
    for i in range(36):
        sliding.add(start + i * period, 100)
    assert len(sliding) == 16  # the last 0.5 s only


async def test_hz_on_the_demo_skeleton_during_a_replay_is_30() -> None:
    config = private_config()
    with Bus.open(config) as bus:
        key = bus.keys.skeleton
        proc = await beyond(config, "hz", key, "--count", "60", "--json")
        bw = await beyond(config, "bw", key, "--count", "60", "--json")
        stop = asyncio.Event()
        try:
            assert proc.stderr is not None and proc.stdout is not None
            assert bw.stderr is not None
            await wait_line(proc.stderr, "listening on")
            await wait_line(bw.stderr, "listening on")
            player = asyncio.create_task(
                replay(
                    bus,
                    DEMO,
                    rate=1.0,
                    robot=config.robot,
                    topics=["beyond/*/sensors/skeleton"],
                    loop=True,
                    stop=stop,
                )
            )
            heard = asyncio.create_task(proc.communicate())
            await asyncio.wait([heard, player], timeout=90, return_when="FIRST_COMPLETED")
            assert heard.done(), "beyond hz did not count 60 messages"
            out, _ = heard.result()
            bw_out, _ = await asyncio.wait_for(bw.communicate(), 90)
        finally:
            stop.set()
            for p in (proc, bw):
                if p.returncode is None:
                    p.kill()
                    await p.wait()
        await player
    assert proc.returncode == 0
    last = json.loads(out.decode().splitlines()[-1])
    assert last["key"] == key and last["count"] >= 2
    assert 29.0 <= last["stamp_hz"] <= 31.0, last
    assert last["arrival_hz"] > 0 and last["mean_bytes"] > 0
    band = json.loads(bw_out.decode().splitlines()[-1])
    assert band["key"] == key and band["min_bytes"] <= band["mean_bytes"] <= band["max_bytes"]
    per_message = band["bytes_per_s"] / band["arrival_hz"]  # = mean size of the window's gaps
    assert band["min_bytes"] <= per_message <= band["max_bytes"]


class Relay(Service):
    name = "relay"

    async def setup(self) -> None:
        self.out = self.publisher(self.bus.keys.gesture_segment, s.GestureSegment)
        self.subscribe(self.bus.keys.skeleton, s.SkeletonFrame, self.on_frame)

    def on_frame(self, frame: s.SkeletonFrame) -> None:
        pass


async def test_info_names_publishers_and_subscribers_from_health() -> None:
    config = private_config()
    with Bus.open(config) as bus:
        service = Relay(bus=bus, health_period=0.2)
        task = asyncio.create_task(service.run(install_signals=False))
        try:
            await asyncio.wait_for(service.started.wait(), 20)
            proc = await beyond(config, "info", bus.keys.skeleton, "--json", "--duration", "2")
            out, err = await asyncio.wait_for(proc.communicate(), 60)
            seg = await beyond(config, "info", bus.keys.gesture_segment, "--json")
            seg_out, _ = await asyncio.wait_for(seg.communicate(), 60)
        finally:
            service.stop()
            await asyncio.wait_for(task, 10)
    assert proc.returncode == 0, err.decode()
    info = json.loads(out)
    assert info["type"] == "SkeletonFrame" and info["subscribers"] == ["relay"]
    assert info["publishers"] == [] and info["any_subscriber"] is True
    assert info["wire_encoding"] == "application/msgpack;SkeletonFrame/v1"
    assert json.loads(seg_out)["publishers"] == ["relay"]


async def test_info_never_says_no_publisher_of_what_it_heard() -> None:
    """A live service heard on the key is among its publishers, even when its health does not
    answer (as a service just started, or one whose session `info` has not met yet): `info`
    printed "publishers: none" beside "heard from: ingest"."""
    config = private_config()
    (frame,) = skeleton_frames(1)
    header = msgspec.structs.replace(frame.header, source="ingest")
    frame = msgspec.structs.replace(frame, header=header)
    with Bus.open(config) as bus:
        bus.declare_token(bus.keys.alive("ingest"))  # alive, no health queryable
        pub = bus.publisher(bus.keys.skeleton, s.SkeletonFrame)
        proc = await beyond(config, "info", bus.keys.skeleton, "--json", "--duration", "2")
        await pub.wait_matching(timeout=60)  # info has subscribed: it hears what follows
        for _ in range(5):
            pub.put(frame)
        out, err = await asyncio.wait_for(proc.communicate(), 60)
    assert proc.returncode == 0, err.decode()
    info = json.loads(out)
    assert info["heard_from"] == ["ingest"] and info["publishers"] == ["ingest"]
    assert info["no_health"] == ["ingest"]


async def test_pub_sends_a_valid_message_and_refuses_an_invalid_one() -> None:
    config = private_config()
    with Bus.open(config) as bus:
        sub = bus.subscribe(bus.keys.skeleton, s.SkeletonFrame)
        text = '{"frame": 7, "joints": {"head": {"position": [0.1, 0.2, 1.5]}}}'
        proc = await beyond(config, "pub", bus.keys.skeleton, "SkeletonFrame", text)
        got = await sub.recv(60)
        await asyncio.wait_for(proc.wait(), 60)
    assert proc.returncode == 0
    assert got.message.frame == 7 and got.message.joints["head"].position == (0.1, 0.2, 1.5)
    assert got.message.header.source == "beyond-pub" and got.message.header.stamp > 0
    bad = '{"frame": 7, "joints": {"head": {"position": [0.1, 0.2, 1.5], "confidence": 2}}}'
    key = f"beyond/{config.robot}/sensors/skeleton"
    rc, _, err = run_cli(config, "pub", key, "SkeletonFrame", bad)
    assert rc == 2 and len(err.strip().splitlines()) == 1
    assert "confidence" in err and "<= 1.0" in err


async def test_pub_sends_again_what_echo_json_printed() -> None:
    """A line of `beyond echo --json` is what `beyond pub` takes, as it is: the same message
    arrives again (header and all); the line of another key is refused."""
    config = private_config()
    (sent,) = skeleton_frames(1)
    with Bus.open(config) as bus:
        key = bus.keys.skeleton
        echo = await beyond(config, "echo", key, "--json", "--count", "1")
        publisher = bus.publisher(key, s.SkeletonFrame)
        await publisher.wait_matching(timeout=60)  # echo has subscribed
        publisher.put(sent)
        line, err = await asyncio.wait_for(echo.communicate(), 60)
        assert echo.returncode == 0, err.decode()
        sub = bus.subscribe(key, s.SkeletonFrame)
        pub = await asyncio.create_subprocess_exec(
            *BEYOND, "pub", key, "SkeletonFrame", "-",
            env=env_for(config), stdin=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
        )  # fmt: skip
        _, err = await asyncio.wait_for(pub.communicate(line), 60)
        assert pub.returncode == 0, err.decode()
        got = await sub.recv(60)
    assert got.message == sent
    other = f"beyond/{config.robot}/gesture/posterior"
    rc, _, err = run_cli(config, "pub", other, "ActionPosterior", line.decode())
    assert rc == 2 and len(err.strip().splitlines()) == 1
    assert f"heard on '{key}'" in err


@pytest.mark.parametrize(
    "args, says",
    [
        (["echo", "beyond/r/nope"], "unknown key 'beyond/r/nope'"),
        (["hz", "beyond/r/sensors/skeletn"], "unknown key 'beyond/r/sensors/skeletn'"),
        (["bw", "nope"], "valid: beyond/"),
        (["info", "beyond/r/sensors/*"], "unknown key"),
        (["pub", "beyond/r/sensors/skeleton", "Skeleton", "{}"], "unknown message type"),
        (["pub", "beyond/r/sensors/skeleton", "SkeletonFrame", "{"], "not valid JSON"),
        (["pub", "beyond/r/sensors/skeleton", "SkeletonFrame", '{"frame": "x"}'], "$.frame"),
        (["replay", str(DEMO), "--remap", "nocolon"], "bad remap"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(args: list[str], says: str) -> None:
    rc, _, err = run_cli(private_config(), *args)
    assert rc == 2, err
    assert len(err.strip().splitlines()) == 1 and says in err, err


def test_exported_schemas_validate_real_messages(tmp_path: Path) -> None:
    rc, _, err = run_cli(private_config(), "schemas", "export", str(tmp_path / "out"))
    assert rc == 0, err
    out = tmp_path / "out"
    page = (out / "README.md").read_text()
    assert "application/msgpack;SkeletonFrame/v1" in page
    frame = skeleton_frames(1)[0]
    segment = s.GestureSegment(
        header=frame.header, event="end", segment_id=1, frame=3, start_stamp=1, end_stamp=2
    )
    import msgspec

    for message in (frame, segment):
        name = type(message).schema_name()
        wire = json.loads((out / f"{name}.json").read_text())
        jsonschema.validate(json.loads(msgspec.json.encode(message)), wire)
        recorded = json.loads((out / "recording" / f"{name}.json").read_text())
        assert recorded == json.loads(json.dumps(recording_json_schema(type(message))))
        jsonschema.validate(json.loads(to_recording_json(message)), recorded)
        with pytest.raises(jsonschema.ValidationError):  # the forms differ where stamps are
            jsonschema.validate(json.loads(msgspec.json.encode(message)), recorded)
    assert len(list(out.glob("*.json"))) == len(s.REGISTRY)


async def test_replay_starts_paused_steps_and_remaps() -> None:
    config = private_config()
    control = ReplayControl(paused=True)
    remap = remapper([f"beyond/{config.robot}/sensors:beyond/{config.robot}/other"])
    assert remap is not None
    with Bus.open(config) as bus:
        target = f"beyond/{config.robot}/other/skeleton"
        sub = bus.subscribe(target, s.SkeletonFrame, Delivery(queue=4096))
        probe = bus.publisher(target, s.SkeletonFrame)
        await probe.wait_matching(timeout=30)
        got: list[int] = []
        player = asyncio.create_task(
            replay(
                bus,
                DEMO,
                rate=None,
                robot=config.robot,
                topics=["beyond/*/sensors/skeleton"],
                end=1.0,
                remap=remap,
                control=control,
                on_message=lambda item: got.append(item.publish_time),
            )
        )
        for _ in range(3):
            control.step()
        first = [await sub.recv(60) for _ in range(3)]
        assert len(got) == 3 and not player.done()  # held: three steps, three messages
        control.toggle()
        stats = await asyncio.wait_for(player, 60)
    assert [r.key for r in first] == [target] * 3
    expected = [r.message() for r in read_recording(DEMO, topics=["beyond/*/sensors/skeleton"])]
    assert [r.message for r in first] == expected[:3]
    assert got[:3] == [m.header.stamp for m in expected[:3]]
    assert stats.messages == sum(1 for m in expected if m.header.stamp - got[0] <= 10**9)
