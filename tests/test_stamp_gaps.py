"""A gap in the stamps is not hostile (issue 39): a recording whose stamps jump one hour after
skeleton frame 150 (a robot left idle, then resumed) gives the lines `beyond analyse` gives, in
`beyond up --rate 0` as offline, and the run ends."""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest
from busutil_net import env_for, private_config, run_beyond

import beyond_self.schemas as s
from beyond_self.runtime.recording.reader import inspect_recording, read_recording
from beyond_self.runtime.recording.replay import restamped
from beyond_self.runtime.recording.writer import RecordingWriter

RECORDING = Path(__file__).resolve().parent.parent / "recordings" / "three-actions.mcap"
HOUR_NS = 3600 * 10**9
GAP_AFTER_FRAME = 150


def hour_gap_recording(path: Path) -> int:
    """three-actions.mcap with every message stamped after skeleton frame 150 (camera frames
    included) one hour later; the stamp of frame 150."""
    items = [(item.key, item.message()) for item in read_recording(RECORDING)]
    cut = next(
        m.header.stamp
        for _, m in items
        if isinstance(m, s.SkeletonFrame) and m.frame == GAP_AFTER_FRAME
    )
    info = inspect_recording(RECORDING)
    with RecordingWriter(path, metadata=info.metadata.get("beyond")) as writer:
        for key, message in items:
            late = message.header.stamp > cut
            writer.write(key, restamped(message, HOUR_NS) if late else message)
    return cut


def gesture_lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.startswith("gesture ")]


@pytest.mark.slow
async def test_an_hour_gap_gives_the_offline_lines_at_rate_max(tmp_path: Path) -> None:
    gap = tmp_path / "gap.mcap"
    cut = hour_gap_recording(gap)
    stamps = [i.message().header.stamp for i in read_recording(gap) if "skeleton" in i.key]
    jumps = [b - a for a, b in itertools.pairwise(stamps) if b - a > HOUR_NS // 2]
    assert len(jumps) == 1 and stamps[GAP_AFTER_FRAME - 1] == cut, jumps
    config = private_config()
    env = {**env_for(config), "BEYOND_LOG_FORMAT": "text"}
    code, offline, errors = await run_beyond(
        ["analyse", str(gap)], env=env, cwd=tmp_path, timeout=60
    )
    assert code == 0, errors[-2000:]
    assert len(gesture_lines(offline)) > 3
    up = ["up", "--recording", str(gap), "--rate", "0", "--no-live", "--timeout", "50"]
    try:
        code, printed, errors = await run_beyond(up, env=env, cwd=tmp_path, timeout=60)
    except TimeoutError:
        pytest.fail("beyond up on the hour-gap recording did not end within a minute")
    assert code == 0, printed + errors[-3000:]
    assert gesture_lines(printed) == gesture_lines(offline), printed + errors[-3000:]
