"""The speech service speaks with espeak-ng when installed (CI installs it), and prints when not."""

from __future__ import annotations

import asyncio
import shutil
import wave
from pathlib import Path

import pytest
from busutil_net import private_config

import beyond_self.schemas as s
from beyond_self.runtime.bus.config import BusConfig
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.resilience.effect_log import LOG_START, EffectLog
from beyond_self.runtime.self_report import RESTARTS_ENV
from beyond_self.schemas import Keys, Message
from beyond_self.services.speech import SpeechSynthesizer


def test_synthesizes_a_real_wav_with_espeak(tmp_path: Path) -> None:
    if shutil.which("espeak-ng") is None:
        pytest.skip("espeak-ng is not installed (apt-get install espeak-ng; .ci/run does)")
    speech = SpeechSynthesizer(out_dir=str(tmp_path))
    wav = tmp_path / "a.wav"
    assert speech.synthesize("he taps the ball and the ball rolls", wav)
    with wave.open(str(wav)) as w:
        seconds = w.getnframes() / w.getframerate()
    assert 1.0 < seconds < 6.0  # nine words at 150 words per minute


def test_without_a_synthesizer_it_reports_false(tmp_path: Path) -> None:
    speech = SpeechSynthesizer(out_dir=str(tmp_path))
    speech.espeak = None  # as on a machine without espeak-ng
    assert speech.synthesize("he taps the ball", tmp_path / "b.wav") is False
    assert not (tmp_path / "b.wav").exists()


def description(gesture: int) -> s.Description:
    header = s.Header(version=1, source="test", seq=gesture, stamp=1_000 + gesture)
    sentence = s.ScoredSentence(text=f"he taps the box {gesture}", score=-1.0)
    return s.Description(
        header=header, segment_id=gesture, sentences=[sentence], evidence=s.Evidence()
    )


async def say(
    out: Path, gestures: list[int], predecessor: s.Ledger | None, config: BusConfig
) -> SpeechSynthesizer:
    """A speech service started beside peers that keep `predecessor` (the last ledger they
    heard from a speech service before it was killed), given the descriptions of `gestures`."""
    with Bus.open(config) as others, Bus.open(config) as bus:
        if predecessor is not None:
            kept = predecessor

            async def answer(_key: str, _request: None) -> list[tuple[str, Message]]:
                return [(others.keys.ledger("speech"), kept)]

            others.queryable(others.keys.ledger(), None, answer)
        speech = SpeechSynthesizer(bus=bus, out_dir=str(out), health_period=0.05)
        speech.espeak = None  # what was said is the log; no WAVs needed
        task = asyncio.create_task(speech.run(install_signals=False))
        await asyncio.wait_for(speech.started.wait(), 30)
        pub = others.publisher(others.keys.description, s.Description)
        await pub.wait_matching(timeout=10)
        for gesture in gestures:
            pub.put(description(gesture))
        while speech.spoken + speech._ledgers.duplicates < len(gestures):
            await asyncio.sleep(0.02)  # every description handled: said or skipped
        speech.stop()
        await asyncio.wait_for(task, 20)
    return speech


def said(out: Path) -> list[int]:
    return [int(line.split("\t")[1]) for line in (out / "speech.log").read_text().splitlines()]


async def test_a_restarted_speech_service_does_not_repeat_what_its_log_says_was_said(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """SIGKILLed after saying gesture 2 but before its ledger reached anyone: the others keep
    a ledger saying 1 only. Its successor gets 2 again (a publisher's cache) and the log, not
    the stale ledger, keeps it from saying it twice. Its supervisor tells it that it was
    restarted, so it asks until the predecessor's ledger is among the answers (a session just
    opened may not know the others' queryable yet: asked once, it said all four, seen once)."""
    monkeypatch.setenv(RESTARTS_ENV, "1")
    log = tmp_path / "speech.log"
    log.write_text("1\t0\t-\tan earlier run, before this run's first speech service\n")
    start = log.stat().st_size
    log.write_text(log.read_text() + "1001\t1\t-\tone\n1002\t2\t-\ttwo\n")
    header = s.Ledger.original_header("speech", 3, 1_001)
    config = private_config()
    key = Keys(robot=config.robot).description
    stale = s.Ledger(
        header=header, service="speech", handled={key: {"description": [(1, 0, 0)]}},
        resume={LOG_START: start},
    )  # fmt: skip
    speech = await say(tmp_path, [1, 2, 3, 4], stale, config)
    assert speech.spoken == 2 and speech._ledgers.duplicates == 2
    assert said(tmp_path) == [0, 1, 2, 3, 4]


async def test_a_first_speech_service_says_what_an_earlier_run_logged(tmp_path: Path) -> None:
    """No predecessor in this run: lines of an earlier run (same gestures) count for nothing,
    and the run's part of the log starts where the file ended."""
    (tmp_path / "speech.log").write_text("1001\t1\t-\tone\n1002\t2\t-\ttwo\n")
    speech = await say(tmp_path, [1, 2], None, private_config())
    assert speech.spoken == 2 and speech._ledgers.duplicates == 0
    assert said(tmp_path) == [1, 2, 1, 2]
    assert speech._ledgers.predecessor() == {}
    assert speech._ledgers.resume == {LOG_START: len("1001\t1\t-\tone\n1002\t2\t-\ttwo\n")}


def test_the_log_reads_whole_lines_and_never_appends_to_a_torn_one(tmp_path: Path) -> None:
    """A line cut short (the machine lost power mid-write) is not taken as said, and the next
    sentence starts a line of its own."""
    log = EffectLog(tmp_path / "speech.log")
    log.path.write_text("1001\t1\t-\tone\n1002\t2\t-\tt")
    assert log.gestures_since(0) == [1]
    assert log.gestures_since(log.size()) == []
    log.append(1002, 2, "-", "two")
    assert log.path.read_text().splitlines()[-1] == "1002\t2\t-\ttwo"
    assert log.gestures_since(0) == [1, 2, 2]  # the fragment, now a line, and the sentence
    assert log.gestures_since(10**6) == [], "a log shorter than the offset: replaced since"
