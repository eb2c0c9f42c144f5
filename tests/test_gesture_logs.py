"""YARP hand-log reader and the feature function."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from beyond_self.cognition.gestures.features import extract_features, features_from_joints
from beyond_self.cognition.gestures.logs import parse_frames, read_hand_log
from beyond_self.core.errors import InputError


def _write(tmp_path: Path, text: str) -> Path:
    folder = tmp_path / "rec"
    folder.mkdir()
    (folder / "data.log").write_text(text)
    return folder


def test_reads_fields_in_order(tmp_path: Path) -> None:
    folder = _write(tmp_path, "-1 100.5 1 2 3\n7 100.6 -4.5 5e2 6\n\n")
    log = read_hand_log(folder)
    assert len(log) == 2
    assert log.seq.tolist() == [-1, 7]
    assert log.time.tolist() == [100.5, 100.6]
    assert log.xyz.tolist() == [[1, 2, 3], [-4.5, 500, 6]]
    assert read_hand_log(folder / "data.log").xyz.shape == (2, 3)


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("-1 1.0 1 2\n", "expected 5 fields"),
        ("-1 1.0 1 2 3 4\n", "expected 5 fields"),
        ("-1 1.0 1 x 3\n", "non-numeric"),
        ("-1 1.0 1 nan 3\n", "non-finite"),
        ("-1 1.0 1 inf 3\n", "non-finite"),
    ],
)
def test_malformed_lines_name_the_line(tmp_path: Path, text: str, needle: str) -> None:
    folder = _write(tmp_path, "-1 0.5 0 0 0\n" + text)
    with pytest.raises(InputError, match=needle) as err:
        read_hand_log(folder)
    assert ":2:" in str(err.value)
    assert "\n" not in str(err.value)


def test_too_short_and_missing(tmp_path: Path) -> None:
    folder = _write(tmp_path, "-1 0.5 0 0 0\n")
    with pytest.raises(InputError, match="at least 5"):
        read_hand_log(folder, min_frames=5)
    with pytest.raises(InputError, match="does not exist"):
        read_hand_log(tmp_path / "nowhere")


def test_frame_ranges_are_one_based_inclusive() -> None:
    assert parse_frames("121:214", 384) == slice(120, 214)
    assert parse_frames(None, 10) == slice(0, 10)
    assert parse_frames("3:", 10) == slice(2, 10)
    assert parse_frames(":4", 10) == slice(0, 4)
    for bad in ("0:5", "5:4", "1:11", "a:b", "1:2:3"):
        with pytest.raises(InputError):
            parse_frames(bad, 10)


def test_article_log(shared_data: Path) -> None:
    log = read_hand_log(shared_data / "saponaro2019/human_data/tap_notable_seated_1")
    assert len(log) == 384
    first = log.frames(121, 121)[0]
    # frame 121 of the file, counted by hand from the text
    line = (shared_data / "saponaro2019/human_data/tap_notable_seated_1/data.log").read_text()
    expected = [float(v) for v in line.splitlines()[120].split()[2:]]
    assert first.tolist() == expected
    assert 25 < log.fps < 35


def test_features_torso_relative_and_normalised() -> None:
    hand = np.array([[0.33, 0.23, 1.34], [0.0, 0.0, 2.0]])
    torso = np.array([[0.0, 0.0, 2.0], [0.0, 0.0, 2.0]])
    f = extract_features(hand, torso)
    np.testing.assert_allclose(f, [[1.0, 1.0, -2.0], [0.0, 0.0, 0.0]])
    # logs: already torso-relative, 1000 x body units
    np.testing.assert_allclose(
        extract_features([1000.0, -500.0, 250.0], scale=0.001), [[1, -0.5, 0.25]]
    )
    joints = {"right_hand": hand, "torso": torso}
    np.testing.assert_allclose(features_from_joints(joints), f)
    with pytest.raises(InputError):
        extract_features(np.zeros((4, 2)))
    with pytest.raises(InputError):
        extract_features(np.zeros((2, 3)), np.zeros((3, 3)))
    with pytest.raises(InputError):
        extract_features([np.nan, 0, 0])
