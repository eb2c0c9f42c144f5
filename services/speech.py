"""Speech: speaks the best sentence of every final description with a real synthesizer.

The synthesizer is espeak-ng through its command line: each sentence is written to a WAV file in
`out_dir` (named by robot time stamp and gesture) and listed in `speech.log` next to it; with
`play` on it is also spoken aloud. Without espeak-ng the service says so once and prints the
sentences instead. To drop in another synthesizer, subclass and override `synthesize` (see the
README's recipe): everything else — subscription, health, malformed input, saying each sentence
once — is inherited. Once: a restarted speech service takes its predecessor's record of what was
said (runtime.ledger) and does not say it again.
"""

from __future__ import annotations

import logging
import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

from beyond_self.runtime.delivery import EVENTS
from beyond_self.runtime.log import event
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
        out_dir: str = "out/speech",
        voice: str = "en",
        words_per_minute: int = 150,
        play: bool = False,
        **base: Any,
    ) -> None:
        super().__init__(**base)
        self.out_dir = Path(out_dir)
        self.voice = voice
        self.wpm = words_per_minute
        self.play = play
        self.espeak = shutil.which("espeak-ng")
        self.spoken = 0

    async def setup(self) -> None:
        self.out_dir.mkdir(parents=True, exist_ok=True)
        if self.espeak is None:
            event(self.log, logging.WARNING, "espeak-ng not found: printing descriptions instead")
        # once: a restarted speech service does not say again what its predecessor said
        self.subscribe(
            self.bus.keys.description, Description, self.on_description, EVENTS, once=True
        )

    def on_description(self, msg: Description) -> None:
        if not msg.final or not msg.sentences:
            return
        text = msg.sentences[0].text
        wav = self.out_dir / f"{msg.header.stamp}-gesture{msg.segment_id}.wav"
        spoken = self.synthesize(text, wav)
        with (self.out_dir / "speech.log").open("a", encoding="utf-8") as log:
            log.write(
                f"{msg.header.stamp}\t{msg.segment_id}\t{wav.name if spoken else '-'}\t{text}\n"
            )
        self.spoken += 1
        print(text, flush=True)

    def synthesize(self, text: str, wav: Path) -> bool:
        """Say `text` into `wav`; False when no synthesizer is installed."""
        if self.espeak is None:
            return False
        # written aside and renamed: a synthesizer orphaned by a killed service, still writing
        # the same sentence, never leaves a torn file
        part = wav.with_name(f"{wav.name}.{os.getpid()}.part")
        cmd = [self.espeak, "-v", self.voice, "-s", str(self.wpm), "-w", str(part), text]
        subprocess.run(cmd, check=True, capture_output=True, timeout=30)
        part.replace(wav)
        if self.play:
            subprocess.run([self.espeak, "-v", self.voice, "-s", str(self.wpm), text], timeout=30)
        return True
