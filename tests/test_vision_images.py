"""Frame files: PPM/PGM/PNG read and write, and one-line errors for broken files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from beyond_self.cognition.vision.color import lab_to_rgb, rgb_to_lab
from beyond_self.cognition.vision.images import as_frame, decode_pnm, read_image, write_image
from beyond_self.core.errors import InputError


def _frame() -> np.ndarray:
    rng = np.random.default_rng(0)
    return rng.integers(0, 256, (7, 11, 3), dtype=np.uint8)


@pytest.mark.parametrize("suffix", [".ppm", ".png"])
def test_write_then_read_is_lossless(tmp_path: Path, suffix: str) -> None:
    img = _frame()
    path = write_image(tmp_path / f"f{suffix}", img)
    back = read_image(path)
    assert back.dtype == np.uint8 and back.shape == (7, 11, 3)
    assert np.array_equal(back, img)


def test_ascii_ppm_with_comments_and_16_bit_binary() -> None:
    ascii_ppm = b"P3\n# a comment\n2 1\n# another\n255\n255 0 0  0 0 255\n"
    assert decode_pnm(ascii_ppm).tolist() == [[[255, 0, 0], [0, 0, 255]]]
    pgm16 = b"P5\n2 1\n65535\n" + np.array([0, 65535], dtype=">u2").tobytes()
    assert decode_pnm(pgm16).tolist() == [[[0, 0, 0], [255, 255, 255]]]


def test_wrong_size_is_refused(tmp_path: Path) -> None:
    path = write_image(tmp_path / "f.ppm", _frame())
    with pytest.raises(InputError, match="11x7; expected 320x240"):
        read_image(path, size=(320, 240))


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"", "empty file"),
        (b"P6\n320 240\n255\n" + b"\0" * 100, "truncated"),
        (b"P6\n320", "truncated PPM header"),
        (b"P6\nab cd\n255\n", "malformed PPM header"),
        (b"GIF89a....", "neither PPM/PGM nor PNG"),
        (b"\x89PNG\r\n\x1a\n garbage", "not a readable PNG"),
    ],
)
def test_broken_files_give_one_line_errors(tmp_path: Path, content: bytes, message: str) -> None:
    suffix = ".png" if content.startswith(b"\x89PNG") else ".ppm"
    path = tmp_path / f"bad{suffix}"
    path.write_bytes(content)
    with pytest.raises(InputError, match=message) as info:
        read_image(path)
    assert "\n" not in str(info.value)


def test_missing_file_and_unknown_suffix(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="does not exist"):
        read_image(tmp_path / "nope.ppm")
    (tmp_path / "x.jpg").write_bytes(b"\xff\xd8")
    with pytest.raises(InputError, match="suffix"):
        read_image(tmp_path / "x.jpg")


def test_as_frame_converts_grey_float_and_rgba_and_refuses_empty() -> None:
    assert as_frame(np.full((2, 3), 7, np.uint8)).shape == (2, 3, 3)
    assert as_frame(np.ones((2, 2, 3)))[0, 0].tolist() == [255, 255, 255]
    assert as_frame(np.zeros((2, 2, 4), np.uint8)).shape == (2, 2, 3)
    with pytest.raises(InputError, match="empty"):
        as_frame(np.zeros((0, 5, 3), np.uint8))
    with pytest.raises(InputError, match="shape"):
        as_frame(np.zeros((2, 2, 2), np.uint8))


def test_cielab_of_reference_colours() -> None:
    # CIE L*a*b* (D65) of sRGB white, black, red, green, blue, from the standard definitions
    expected = {
        (255, 255, 255): (100.0, 0.0, 0.0),
        (0, 0, 0): (0.0, 0.0, 0.0),
        (255, 0, 0): (53.24, 80.09, 67.20),
        (0, 255, 0): (87.73, -86.18, 83.18),
        (0, 0, 255): (32.30, 79.19, -107.86),
    }
    for rgb, lab in expected.items():
        assert np.allclose(rgb_to_lab(np.array(rgb)), lab, atol=0.05), rgb
    rgb = np.random.default_rng(1).integers(0, 256, (50, 3))
    assert np.allclose(lab_to_rgb(rgb_to_lab(rgb)), rgb, atol=1e-6)
