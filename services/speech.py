"""Speech: speaks the best sentence of every final description with a real synthesizer.

The synthesizer is espeak-ng through its command line: each sentence is rendered to a WAV file
in `out_dir` (named by robot time stamp and gesture; default `speech/` under the run's output
folder, runtime.outputs), listed in `speech.log` next to it, and with
`play` on spoken aloud. Without espeak-ng the service says so once and prints the sentences
instead. To drop in another synthesizer, subclass and override `synthesize` (see the README's
recipe): everything else — subscription, health, malformed input, saying each sentence once —
is inherited.

Once, across a SIGKILL: the bus record of what was said (runtime.ledger) reaches the other
services a moment after the sentence, so a kill in that moment would let a restarted speech
service say it again. The speech log is the record that cannot lag: a sentence is rendered (no
effect yet), then its line is written in one append and synced (the commit), then it is played.
A restarted service reads the lines its run wrote (from the offset its first instance left in
its checkpoint) and does not say them again; a kill before the commit renders the same WAV
again, one after it may cut the sentence short but never repeats it.
"""

from __future__ import annotations

import argparse
import logging
import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

from beyond_self.runtime.delivery import EVENTS
from beyond_self.runtime.log import event
from beyond_self.runtime.outputs import DESCRIPTION, service_out_dir
from beyond_self.runtime.service import Service
from beyond_self.schemas import Description
from beyond_self.schemas.identity import Identity

LOG_START = "log_start"  # checkpoint: the speech log's size when this run's speech began


class SpeechLog:
    """`speech.log`: one line per sentence said (stamp, gesture, WAV or '-', text)."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def size(self) -> int:
        return self.path.stat().st_size if self.path.exists() else 0

    def gestures_since(self, offset: int) -> list[int]:
        """The gestures of the complete lines written from byte `offset` on (a file that
        shrank since, replaced by hand, holds none of them)."""
        if self.size() <= offset:
            return []
        with self.path.open("rb") as f:
            f.seek(offset)
            lines = f.read().split(b"\n")[:-1]  # the last piece is not a complete line
        fields = (line.split(b"\t") for line in lines)
        return [int(f[1]) for f in fields if len(f) >= 4 and f[1].isdigit()]

    def append(self, stamp: int, gesture: int, wav: str, text: str) -> None:
        """One write on an append-only descriptor (a SIGKILL cannot tear it), then synced; on
        a line of its own even after one a power loss cut short."""
        line = f"{stamp}\t{gesture}\t{wav}\t{text}\n".encode()
        fd = os.open(self.path, os.O_RDWR | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            size = os.fstat(fd).st_size
            if size and os.pread(fd, 1, size - 1) != b"\n":
                line = b"\n" + line
            os.write(fd, line)
            os.fsync(fd)
        finally:
            os.close(fd)


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
        self.said = SpeechLog(self.out_dir / "speech.log")

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
        self._take_what_the_run_said()
        # once: a restarted speech service does not say again what its predecessor said
        self.subscribe(
            self.bus.keys.description, Description, self.on_description, EVENTS, once=True
        )

    def _take_what_the_run_said(self) -> None:
        """A restarted instance: the sentences of its run's speech log count as said. The
        first: its run's part of the log starts at the log's present end."""
        start = self.ledgers.predecessor().get(LOG_START)
        if start is not None:
            keys = self.bus.keys
            gestures = self.said.gestures_since(start)
            for gesture in gestures:
                said = Identity(keys.robot, gesture, "description")
                self.ledgers.handled.add(keys.description, said)
            event(self.log, logging.INFO, "took the speech log", said=len(gestures))
        else:
            start = self.said.size()
        self.ledgers.checkpoint({}, {LOG_START: start})

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
