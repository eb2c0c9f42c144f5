"""The speech drop-in of docs/how-to/speech.md, run as a user runs it: `docs/examples/my_speech.py`
beside `beyond up --skip speech`, saying every description the pipeline prints into WAVs and its
speech log; without its synthesizer it says so in one line before starting.

The end-to-end test needs espeak-ng (CI installs it) and skips only without it.
"""

from __future__ import annotations

import asyncio
import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from busutil_net import REPO, env_for, private_config, run_beyond

from beyond_self.runtime.bus.session import Bus

EXAMPLE = REPO / "docs" / "examples" / "my_speech.py"
RECORDING = REPO / "recordings" / "touch-box.mcap"


def test_without_its_synthesizer_it_says_so_in_one_line(tmp_path: Path) -> None:
    empty = tmp_path / "bin"
    empty.mkdir()
    env = env_for(private_config(), PATH=str(empty))
    done = subprocess.run(
        [sys.executable, str(EXAMPLE)],
        env=env,
        cwd=tmp_path,
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2
    assert done.stderr.splitlines() == [
        "my_speech.py: error: espeak-ng is not installed; install it (Debian/Ubuntu: sudo apt "
        "install espeak-ng) or put it on PATH"
    ]


def test_help_says_what_it_needs() -> None:
    done = subprocess.run(
        [sys.executable, str(EXAMPLE), "--help"], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0
    assert "Needs: beyond-self" in done.stdout and "sudo apt install espeak-ng" in done.stdout
    assert "--out-dir DIR" in done.stdout


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng is not installed")
async def test_it_says_what_up_describes_beside_up_skip_speech(tmp_path: Path) -> None:
    config = private_config()
    env = env_for(config)
    said, outputs = tmp_path / "said", tmp_path / "up"
    speech = subprocess.Popen(
        [sys.executable, str(EXAMPLE), "--out-dir", str(said)],
        env=env,
        cwd=tmp_path,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
    )
    try:
        with Bus.open(config) as bus:
            await bus.wait_alive(bus.keys.alive("speech"), timeout=60)
        rc, out, err = await run_beyond(
            ["up", "--recording", str(RECORDING), "--skip", "speech", "--no-live", "--rate", "0",
             "--out-dir", str(outputs)],
            env=env, cwd=tmp_path, timeout=180,
        )  # fmt: skip
        assert rc == 0, out + err[-3000:]
        described = re.findall(r'^gesture \d+: "(.*)"$', out, re.M)
        assert described, out
        log = said / "speech.log"
        loop = asyncio.get_running_loop()
        deadline = loop.time() + 30
        while len(log.read_text().splitlines() if log.exists() else []) < len(described):
            assert loop.time() < deadline, f"{log} holds fewer than {len(described)} sentences"
            await asyncio.sleep(0.05)
        lines = [line.split("\t") for line in log.read_text().splitlines()]
        assert [fields[-1] for fields in lines] == described
        for fields in lines:
            assert (said / fields[2]).read_bytes()[:4] == b"RIFF"  # a WAV, rendered
        assert not (outputs / "speech").exists()  # up started no speech service of its own
        speech.send_signal(signal.SIGTERM)
        speech.communicate(timeout=60)
        assert speech.returncode == 0
    finally:
        if speech.poll() is None:
            os.kill(speech.pid, signal.SIGKILL)
