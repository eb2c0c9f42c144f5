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
from beyond_self.runtime.config import BusConfig
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
    assert re.search(r"gesture \d: anticipates ObjVel=\w+ .* before the gesture ends", first.stdout)
    # paced or as fast as possible, every run prints the same lines in the same order
    for rate in ("0", "0"):
        again = run_up(recording, tmp_path, config, rate)
        assert again.returncode == 0
        assert again.stdout == first.stdout
    spoken = (tmp_path / "out" / "speech" / "speech.log").read_text().splitlines()
    assert [line.split("\t")[-1] for line in spoken] == [s for _, s in described] * 3


async def test_a_killed_service_restarts_and_is_picked_up() -> None:
    env = {"BEYOND_LOG_FORMAT": "text", "PYTHONPATH": str(Path(__file__).resolve().parent.parent)}
    words = {w: 0.5 for w in DEFAULT_GRAMMAR.vocabulary}
    words.update({"he": 0.99, "taps": 0.99, "the": 0.99, "box": 0.99, "and": 0.99, "slides": 0.99})
    pipeline = Deployment(private_config(), ["describer"], env=env)
    bus = await pipeline.open()
    out = bus.subscribe(bus.keys.description, s.Description)
    pub = bus.publisher(bus.keys.words, s.WordProbabilities)
    first = await pipeline.launch("describer")
    try:
        for round_ in range(2):
            await bus.wait_alive(bus.keys.alive("describer"), timeout=30)
            await pub.wait_matching(timeout=30)
            header = s.Header(version=1, source="test", seq=round_, stamp=round_)
            pub.put(s.WordProbabilities(header=header, segment_id=round_, words=words))
            got = (await out.recv(timeout=20)).message
            assert got.segment_id == round_
            assert got.sentences[0].text == "he taps the box and the box slides"
            if round_ == 0:  # kill it hard, and start a new one: the bus picks it up
                first.process.send_signal(signal.SIGKILL)
                await first.process.wait()
                await bus.wait_gone(bus.keys.alive("describer"), timeout=30)
                await pipeline.launch("describer")
    finally:
        codes = await pipeline.stop()
    assert first.process.returncode == -signal.SIGKILL
    assert codes == {"describer": 0}  # the new process, stopped cleanly
    await asyncio.sleep(0)


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
