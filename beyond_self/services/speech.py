"""Speech: speaks the best sentence of every final description with a real synthesizer.

espeak-ng renders each sentence to a WAV in `out_dir` (default `speech/` under the run's output
folder, runtime.outputs), listed in `speech.log` beside it, and with `play` spoken aloud; without
espeak-ng the service says so once and prints the sentences. Another synthesizer: subclass and
override `synthesize` (docs/how-to/speech.md). Once, across a SIGKILL: the bus ledger reaches the
others a moment after the sentence, so the speech log is the record that cannot lag: render, then
append the line and sync (the commit), then play. A restarted service reads the lines its run
wrote and does not say them again; a kill after the commit cuts a sentence short at worst.
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
from beyond_self.runtime.service import Service
from beyond_self.schemas import Description
from beyond_self.schemas.identity import Identity

LOG_START = "log_start"  # checkpoint: the speech log's size when this run's speech began


class SpeechLog:
    """`speech.log`: one line per sentence said (stamp, gesture, WAV or '-', text)."""

    def __init__(self, path: Path, *, sync: bool = True) -> None:
        self.path = path
        self.sync = sync  # also survive a power loss, not only a kill (a synced write costs ms)

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
        """One write on an append-only descriptor (a SIGKILL cannot tear it), then synced
        (`sync`); on a line of its own even after one a power loss cut short."""
        line = f"{stamp}\t{gesture}\t{wav}\t{text}\n".encode()
        fd = os.open(self.path, os.O_RDWR | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            size = os.fstat(fd).st_size
            if size and os.pread(fd, 1, size - 1) != b"\n":
                line = b"\n" + line
            os.write(fd, line)
            if self.sync:
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
        take_what_the_run_said(self, self.said)

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


def take_what_the_run_said(service: Service, said: SpeechLog) -> None:
    """A restarted instance of `service`: the sentences of its run's part of log `said` count
    as said (handled descriptions). The first: its run's part starts at the log's present end,
    kept in its checkpoint (LOG_START)."""
    start = service.ledgers.predecessor().get(LOG_START)
    if start is not None:
        keys = service.bus.keys
        gestures = said.gestures_since(start)
        for gesture in gestures:
            service.ledgers.handled.add(
                keys.description, Identity(keys.robot, gesture, "description")
            )
        event(service.log, logging.INFO, "took the log of what was said", said=len(gestures))
    else:
        start = said.size()
    service.ledgers.checkpoint({}, {LOG_START: start})
