"""my_speech.py: your own speech service, run beside `beyond up --skip speech`.

It says every description with espeak-ng in a voice of its own (American English, a female
variant, slower and higher than the stock service's). Put your synthesizer's command in
`synthesize`, which renders one sentence into a WAV file; everything else is inherited from
beyond's speech service: the subscription, health, bad input, saying each sentence once across
restarts, --out-dir and the bus options.

Needs: beyond-self (the project's venv, or pip install of its wheel) and espeak-ng
(Debian/Ubuntu: sudo apt install espeak-ng).

    beyond up --skip speech        # one terminal
    python my_speech.py            # another, with the same BEYOND_* environment
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

from beyond_self.core.errors import InputError
from beyond_self.services.speech import SpeechSynthesizer

SYNTHESIZER = "espeak-ng"


class MySpeech(SpeechSynthesizer):
    @classmethod
    def check_requirements(cls) -> None:  # checked before the service starts: one line
        if shutil.which(SYNTHESIZER) is None:
            raise InputError(
                f"{SYNTHESIZER} is not installed; install it (Debian/Ubuntu: sudo apt install "
                f"espeak-ng) or put it on PATH"
            )

    def synthesize(self, text: str, wav: Path) -> bool:
        voice = ["-v", "en-us+f3", "-s", "130", "-p", "60"]
        subprocess.run(
            [SYNTHESIZER, *voice, "-w", str(wav), "--stdin"],
            input=text,
            text=True,
            check=True,
            capture_output=True,
            timeout=30,
        )
        return True


if __name__ == "__main__":
    MySpeech.main()
