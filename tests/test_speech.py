"""The speech service speaks with espeak-ng when installed (CI installs it), and prints when not."""

from __future__ import annotations

import shutil
import wave
from pathlib import Path

import pytest

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
