"""The whole pipeline as separate processes (`beyond up`), and a service killed and restarted."""

from __future__ import annotations

import asyncio
import re
import signal
import subprocess
from pathlib import Path

import pytest
from busutil_net import env_for, private_config, skeleton_recording

import beyond_self.schemas as s
from beyond_self.cognition.grammar import DEFAULT_GRAMMAR
from beyond_self.runtime.bus import Bus
from beyond_self.runtime.config import BusConfig
from beyond_self.runtime.delivery import EVENTS
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
           "--no-live", "--timeout", "90"]  # fmt: skip
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
    assert re.search(r"gesture 1: anticipates ObjVel=\w+ .* before the gesture ends", first.stdout)
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


@pytest.mark.slow
def test_demo_watches_the_bundled_recording_and_describes_it(tmp_path: Path) -> None:
    """`make demo`'s job, on a private bus: the tapped ball and the grasped box, in words."""
    env = {**env_for(private_config()), "BEYOND_LOG_FORMAT": "text"}
    cmd = [*BEYOND, "demo", "--no-live"]
    done = subprocess.run(cmd, env=env, cwd=tmp_path, capture_output=True, text=True, timeout=150)
    assert done.returncode == 0, done.stdout + done.stderr[-3000:]
    described = dict(re.findall(r'^gesture (\d+): "(.*)"$', done.stdout, re.M))
    assert set(described) == {"1", "2"}, done.stdout
    assert re.search(VERBS["tap"], described["1"]) and re.search(
        r"\b(ball|sphere)\b", described["1"]
    )
    assert re.search(VERBS["grasp"], described["2"])
    assert re.search(r"\b(box|cube|square)\b", described["2"])
    # the effect of the tap is anticipated while the gesture unfolds
    anticipated = re.findall(
        r"^gesture 1: anticipates ObjVel=(\w+) .* at frame (\d+)", done.stdout, re.M
    )
    ended = int(re.findall(r"^gesture 1: ended at frame (\d+)", done.stdout, re.M)[0])
    assert anticipated and anticipated[-1][0] == "fast" and int(anticipated[-1][1]) < ended
