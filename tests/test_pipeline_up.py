"""The whole pipeline as separate processes (`beyond up`), from a folder of decoy packages and
recorded beside it, and a service killed and restarted."""

from __future__ import annotations

import asyncio
import json
import re
import signal
import subprocess
from pathlib import Path

import pytest
from busutil_net import REPO, env_for, private_config, run_beyond, skeleton_recording
from mcap.reader import make_reader
from third_party_readers import assert_trusted, doctor, js_reports, unsafe_integers

import beyond_self.schemas as s
from beyond_self.cognition.grammar import DEFAULT_GRAMMAR
from beyond_self.cognition.paths import DEMO_RECORDING
from beyond_self.runtime.bus.config import BusConfig
from beyond_self.runtime.bus.delivery import EVENTS
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.recording.reader import inspect_recording, read_recording
from beyond_self.runtime.recording.replay import Player, recorded_cues
from beyond_self.services.deployment import Deployment
from beyond_self.services.launcher import BEYOND

VERBS = {
    "tap": r"\b(taps|tapped|tapping|pushes|pushed|pushing|pokes|poked|poking)\b",
    "grasp": r"\b(grasps|grasped|grasping|picks|picked|picking)\b",
    "touch": r"\b(touches|touched|touching|pokes|poked|poking)\b",
}


def run_up(
    recording: Path, tmp: Path, config: BusConfig, rate: str
) -> subprocess.CompletedProcess[str]:
    env = {**env_for(config), "BEYOND_LOG_FORMAT": "text"}
    cmd = [*BEYOND, "up", "--recording", str(recording), "--rate", rate,
           "--no-live", "--timeout", "90", "--out-dir", str(tmp / "out")]  # fmt: skip
    return subprocess.run(cmd, env=env, cwd=tmp, capture_output=True, text=True, timeout=150)


@pytest.mark.slow
def test_up_describes_every_gesture_with_the_right_verb_and_twice_the_same(tmp_path: Path) -> None:
    recording = tmp_path / "tap-grasp.mcap"
    skeleton_recording(recording, ["tap", "grasp"], seed=3)
    config = private_config()
    first = run_up(recording, tmp_path, config, "2")
    assert first.returncode == 0, first.stdout + first.stderr[-3000:]
    described = re.findall(r'^gesture (\d+): "(.*)"$', first.stdout, re.M)
    assert [g for g, _ in described] == ["1", "2"], first.stdout
    for (_, sentence), action in zip(described, ["tap", "grasp"], strict=True):
        assert re.search(VERBS[action], sentence), (action, sentence)
    assert re.search(r"gesture \d: anticipates ObjVel=\w+ .* before the gesture ends", first.stdout)
    # paced or as fast as possible, every run prints the same lines in the same order
    for rate in ("0", "0"):
        again = run_up(recording, tmp_path, config, rate)
        assert again.returncode == 0
        assert again.stdout == first.stdout
    spoken = (tmp_path / "out" / "speech" / "speech.log").read_text().splitlines()
    assert [line.split("\t")[-1] for line in spoken] == [s for _, s in described] * 3


async def said(log: Path, lines: int, timeout: float = 30.0) -> None:
    """Until the speech service has logged `lines` sentences."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while not (log.exists() and log.read_text().count("\n") >= lines):
        assert loop.time() < deadline, f"{log} holds fewer than {lines} sentences"
        await asyncio.sleep(0.05)


async def restarted(bus: Bus, name: str, timeout: float = 60.0) -> None:
    """Until service `name` answers health as restarted once (its health shows it)."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while loop.time() < deadline:
        replies = await bus.query(bus.keys.health(name), s.ServiceHealth, timeout=2, every=True)
        if any(r.message.restarts == 1 for r in replies):
            return
        await asyncio.sleep(0.05)
    raise AssertionError(f"{name} did not come back within {timeout} s")


async def test_a_killed_service_is_restarted_and_repeats_nothing(tmp_path: Path) -> None:
    """The deployment restarts a describer killed with SIGKILL once its sentence was said. The
    new one says in its health that it was restarted, gets back from the publisher's cache the
    words it had described, and does not describe them again (its predecessor's record, kept by
    the speech service, says it did; and the speech service, its consumer, has the sentence).
    Each sentence said once, too."""
    env = {"BEYOND_LOG_FORMAT": "text", "PYTHONPATH": str(Path(__file__).resolve().parent.parent)}
    words = {w: 0.5 for w in DEFAULT_GRAMMAR.vocabulary}
    words.update({"he": 0.99, "taps": 0.99, "the": 0.99, "box": 0.99, "and": 0.99, "slides": 0.99})
    told: list[tuple[str, str]] = []
    pipeline = Deployment(
        private_config(),
        ["speech", "describer"],
        options={"speech": {"out_dir": str(tmp_path)}},
        env=env,
        on_restart=lambda name, what: told.append((name, what)),
    )
    bus = await pipeline.open()
    out = bus.subscribe(bus.keys.description, s.Description)
    pub = bus.publisher(bus.keys.words, s.WordProbabilities, EVENTS)  # cached, as the reasoner's
    await pipeline.start()
    first = next(p for p in pipeline.processes if p.name == "describer")
    try:
        for round_ in range(2):
            header = s.Header(version=1, source="test", seq=round_, stamp=round_ + 1)
            pub.put(s.WordProbabilities(header=header, segment_id=round_, words=words))
            got = (await out.recv(timeout=30)).message  # a repeat of round 0 would come first
            assert got.segment_id == round_
            assert got.sentences[0].text == "he taps the box and the box slides"
            if round_ == 0:  # once said, kill it hard: the deployment starts a new one
                await said(tmp_path / "speech.log", 1)
                first.process.send_signal(signal.SIGKILL)
                await first.process.wait()
                await restarted(bus, "describer")
        await said(tmp_path / "speech.log", 2)
    finally:
        codes = await pipeline.stop()
    assert first.process.returncode == -signal.SIGKILL
    assert told == [("describer", "killed by SIGKILL; restart 1 in 0.1 s")]
    assert pipeline.restarts["describer"].count == 1
    assert codes == {"speech": 0, "describer": 0}  # the new process, stopped cleanly
    spoken = (tmp_path / "speech.log").read_text().splitlines()
    assert [line.split("\t")[1] for line in spoken] == ["0", "1"]  # each said once


DECOYS = ("schemas", "runtime", "core", "services", "cognition", "beyond", "beyond_self")


def readme_demo_lines() -> list[str]:
    """The gesture lines the README promises the demo prints."""
    text = (REPO / "README.md").read_text(encoding="utf-8")
    blocks = [part.split("```", 1)[0] for part in text.split("```text")[1:]]
    block = next(b for b in blocks if "\ngesture " in b)  # the demo's output, after the picture
    return [line for line in block.splitlines() if line.startswith("gesture ")]


@pytest.mark.slow
async def test_up_from_a_folder_of_decoys_prints_the_readme_and_records_on_one_clock(
    node_modules: Path, tmp_path: Path
) -> None:
    """`beyond up` (the demo recording) run from a folder holding a package of every name we
    import, each raising when imported: no process it starts imports them, and it prints the
    README's gesture lines word for word. `beyond record` beside it (issue 23): every channel
    (data, health, progress, the clock, the end marker) on the stream's clock, so the file spans
    the stream, its log times never step back, `pymcap-cli doctor` finds nothing to say, it
    replays with the stream's timing, and every number a JavaScript reader sees is exact."""
    work = tmp_path / "decoys"
    for name in DECOYS:
        (work / name).mkdir(parents=True)
        (work / name / "__init__.py").write_text("raise ImportError('decoy imported')\n")
    config = private_config()
    env = {**env_for(config), "BEYOND_LOG_FORMAT": "text"}
    out = tmp_path / "up.mcap"
    recorder = subprocess.Popen(
        [*BEYOND, "record", "-o", str(out)],
        env=env,
        cwd=work,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        with Bus.open(config) as bus:  # the recorder listens once it matches a publisher
            await bus.publisher(bus.keys.stream_end, s.StreamEnd).wait_matching(timeout=30)
        code, printed, errors = await run_beyond(
            ["up", "--no-live", "--rate", "0"], env=env, cwd=work, timeout=150
        )
        assert code == 0, printed + errors[-3000:]
        recorder.send_signal(signal.SIGINT)
        assert await asyncio.to_thread(recorder.wait, 30) == 0
    finally:
        if recorder.poll() is None:
            recorder.kill()
            recorder.wait()
    assert "decoy" not in errors
    # the object segmenter's frame describer is stopped and waited for, so its queues are
    # released: multiprocessing's resource tracker used to warn of leaked semaphores at exit
    assert "Warning" not in errors, [line for line in errors.splitlines() if "Warning" in line]
    gestures = [line for line in printed.splitlines() if line.startswith("gesture ")]
    assert gestures == readme_demo_lines()
    recorded, played = inspect_recording(out), inspect_recording(DEMO_RECORDING)
    assert (recorded.start, recorded.end) == (played.start, played.end)  # the stream's span
    times: dict[str, list[int]] = {}
    for item in read_recording(out):
        times.setdefault(item.key, []).append(item.log_time)
        if item.encoding == "json":
            assert list(unsafe_integers(json.loads(item.data))) == [], item.key
    root = f"beyond/{config.robot}"
    for key in ("clock", "health/ingest", "health/speech", "progress/objects", "sensors/end"):
        assert f"{root}/{key}" in times, sorted(times)
    written: dict[str, list[int]] = {}  # as written: what a ROS or Foxglove player walks
    with open(out, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
            written.setdefault(channel.topic, []).append(message.log_time)
    assert written.keys() == times.keys()
    for key, logged in written.items():
        assert logged == sorted(logged), f"{key} steps back in time"
    found = doctor(out)
    assert [f["code"] for f in found["findings"]] == ["NO_ATTACHMENTS"], found
    (report,) = js_reports(node_modules, [out])
    assert_trusted(report, out)
    player = Player(rate=None)  # `beyond replay`'s schedule, as fast as possible and nowhere
    await player.play(recorded_cues(read_recording(out)), lambda cue: None)
    assert player.stats.span_s == (played.end - played.start) / 1e9  # at rate 1, it takes that
