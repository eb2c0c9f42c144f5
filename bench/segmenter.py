"""Object segmenter throughput: frames per second on one core, ours next to a textbook baseline.

Ours (`cognition.vision`): per frame, segmentation against the table model (brightness and
chromaticity distortion, hand split by skin colour, components, refinement) plus every object's
full features (centroid, area, CIELAB colour, shape descriptors). Measured with the table model
learned once per recording (how a camera stream is processed) and with the table estimated from
each frame (single images).

Reference, in the same run on the same frames: the straightforward scipy pipeline a first
version would use: every pixel converted to CIELAB, ΔE against the table model, full-frame
opening and hole filling, `ndimage.label`, and per-object centroid/area/mean colour with
`ndimage` measurement functions. It finds the same objects; it does not split the hand or trim
shadows, so it does less.

Frames come from a simulated tap (the object, the moving hand, shadows, sensor noise) at
320×240 and 640×480. One core: BLAS/OpenMP threads are limited to 1 and the process is pinned.
Ends with one line of JSON.
"""

from __future__ import annotations

import argparse
import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import json  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402

import numpy as np  # noqa: E402
from scipy import ndimage  # noqa: E402

from beyond_self.cognition.vision.background import BackgroundModel  # noqa: E402
from beyond_self.cognition.vision.color import rgb_to_lab  # noqa: E402
from beyond_self.cognition.vision.features import measure  # noqa: E402
from beyond_self.cognition.vision.segmentation import segment  # noqa: E402
from beyond_self.cognition.vision.tabletop import Camera, simulate_experiment  # noqa: E402

SECONDS = 2.0  # per measurement


def frames_for(width: int, height: int) -> list[np.ndarray]:
    rng = np.random.default_rng(7)
    exp = simulate_experiment("tap", "blue", "circle", "medium", rng, camera=Camera(width, height))
    return list(exp.frames)


def ours(bg: BackgroundModel | None) -> Callable[[np.ndarray], int]:
    def run(frame: np.ndarray) -> int:
        seg = segment(frame, bg)
        return len(measure(frame, seg))

    return run


def reference(bg: BackgroundModel) -> Callable[[np.ndarray], int]:
    table_lab = rgb_to_lab(bg.mean)
    square = np.ones((3, 3), dtype=bool)

    def run(frame: np.ndarray) -> int:
        lab = rgb_to_lab(frame)
        delta = np.sqrt(((lab - table_lab) ** 2).sum(axis=2))
        mask = ndimage.binary_opening(delta > 12.0, structure=square)
        mask = ndimage.binary_fill_holes(mask)
        labels, n = ndimage.label(mask, structure=square)
        if n == 0:
            return 0
        index = np.arange(1, n + 1)
        areas = ndimage.sum_labels(mask, labels, index)
        ndimage.center_of_mass(mask, labels, index)
        for c in range(3):
            ndimage.mean(lab[:, :, c], labels, index)
        return int((areas >= 48).sum())

    return run


def fps(fn: Callable[[np.ndarray], int], frames: list[np.ndarray]) -> tuple[float, int]:
    """Frames per second over about SECONDS of repeated passes (after one warm-up pass)."""
    found = sum(fn(f) for f in frames)
    count, start = 0, time.perf_counter()
    while time.perf_counter() - start < SECONDS:
        for f in frames:
            fn(f)
        count += len(frames)
    return count / (time.perf_counter() - start), found


def main() -> None:
    # no options: --help says what it measures and exits
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    results: dict[str, float | int | str] = {"bench": "segmenter", "cores": 1}
    for w, h in ((320, 240), (640, 480)):
        frames = frames_for(w, h)
        bg = BackgroundModel.from_frame(frames[0])
        key = f"{w}x{h}"
        f_ours, n_ours = fps(ours(bg), frames)
        f_self, _ = fps(ours(None), frames)
        f_ref, n_ref = fps(reference(bg), frames)
        results[f"fps_{key}"] = round(f_ours, 1)
        results[f"fps_{key}_background_per_frame"] = round(f_self, 1)
        results[f"reference_fps_{key}"] = round(f_ref, 1)
        results[f"speedup_{key}"] = round(f_ours / f_ref, 2)
        results[f"objects_per_frame_{key}"] = round(n_ours / len(frames), 2)
        results[f"reference_objects_per_frame_{key}"] = round(n_ref / len(frames), 2)
        print(
            f"{key}: ours {f_ours:7.1f} fps (table model per recording), {f_self:7.1f} fps "
            f"(table estimated per frame); reference {f_ref:6.1f} fps; ours/reference "
            f"{f_ours / f_ref:.2f}x; objects/frame ours {n_ours / len(frames):.2f}, "
            f"reference {n_ref / len(frames):.2f} (it counts the hand as an object)"
        )
    results["goal_fps_320x240"] = 60
    results["goal_met"] = "yes" if float(results["fps_320x240"]) >= 60 else "no"
    print(json.dumps(results))


if __name__ == "__main__":
    main()
