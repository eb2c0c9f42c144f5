"""Speech: speaks the best sentence of every final description with a real synthesizer.

espeak-ng renders each sentence to a WAV in `out_dir` (default `speech/` under the run's output
folder, runtime.outputs), listed in `speech.log` beside it, and with `play` spoken aloud; without
espeak-ng the service says so once and prints the sentences. Another synthesizer: subclass and
override `synthesize` (docs/how-to/speech.md). Once, across a SIGKILL: the speech log is the
subscription's `once=` log (runtime.resilience.effect_log): render, then append the line and sync
(the commit), then play. A restarted service does not say again what the log says was said; a
kill after the commit cuts a sentence short at worst.
"""

from __future__ import annotations

import argparse
import logging
import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

from beyond_self.runtime.bus.delivery import EVENTS
from beyond_self.runtime.log import event
from beyond_self.runtime.outputs import DESCRIPTION, service_out_dir
from beyond_self.runtime.resilience.effect_log import EffectLog
from beyond_self.runtime.service import Service
from beyond_self.schemas import Description


class SpeechSynthesizer(Service):
    name = "speech"
    subscribes = ("description",)
    publishes = ()
    serves = ()

    def __init__(
        self,
        *,
        out_dir: str | None = None,
        voice: str = "en",
        words_per_minute: int = 150,
        play: bool = False,
        **base: Any,
    ) -> None:
        super().__init__(**base)
        self.out_dir = Path(out_dir) if out_dir is not None else service_out_dir("speech")
        self.voice = voice
        self.wpm = words_per_minute
        self.play = play
        self.espeak = shutil.which("espeak-ng")
        self.spoken = 0
        self.said = EffectLog(self.out_dir / "speech.log")

    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        parser.add_argument(
            "--out-dir",
            metavar="DIR",
            help=f"where the WAVs and speech.log go (default: speech/ under {DESCRIPTION})",
        )
        parser.add_argument(
            "--play", action="store_true", default=None, help="also play each sentence aloud"
        )

    async def setup(self) -> None:
        self.out_dir.mkdir(parents=True, exist_ok=True)
        if self.espeak is None:
            event(self.log, logging.WARNING, "espeak-ng not found: printing descriptions instead")
        # once: a restarted speech service does not say again what its log says was said
        keys = self.bus.keys
        self.subscribe(keys.description, Description, self.on_description, EVENTS, once=self.said)

    def on_description(self, msg: Description) -> None:
        if not msg.final or not msg.sentences:
            return
        text = msg.sentences[0].text
        wav = self.out_dir / f"{msg.header.stamp}-gesture{msg.segment_id}.wav"
        rendered = self.synthesize(text, wav)
        self.said.append(msg.header.stamp, msg.segment_id, wav.name if rendered else "-", text)
        if rendered and self.play:
            self.speak_aloud(wav, text)
        self.spoken += 1
        print(text, flush=True)

    def synthesize(self, text: str, wav: Path) -> bool:
        """Render `text` into `wav` (nothing heard yet); False when no synthesizer is installed.
        Rendering the same sentence again (a kill before it was logged) gives the same file."""
        if self.espeak is None:
            return False
        # written aside and renamed: a synthesizer orphaned by a killed service, still writing
        # the same sentence, never leaves a torn file
        part = wav.with_name(f"{wav.name}.{os.getpid()}.part")
        cmd = [self.espeak, "-v", self.voice, "-s", str(self.wpm), "-w", str(part), text]
        subprocess.run(cmd, check=True, capture_output=True, timeout=30)
        part.replace(wav)
        return True

    def speak_aloud(self, wav: Path, text: str) -> None:
        """Play the sentence (once it is logged as said)."""
        if self.espeak is not None:
            subprocess.run([self.espeak, "-v", self.voice, "-s", str(self.wpm), text], timeout=30)
