"""An overlay a person can check at a glance: contours, centroids and labels drawn on the frame.

Drawn with matplotlib (already a dependency; it renders text, which plain numpy cannot) onto an
Agg canvas, so the overlay is available as an RGB array (for a service to publish) or a PNG.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from beyond_self.cognition.vision.pipeline import DetectedObject
from beyond_self.cognition.vision.segmentation import Segmentation

_COLORS = ("#00e5ff", "#ff4081", "#ffea00", "#76ff03", "#ff9100", "#d500f9")


def render_overlay(
    frame: np.ndarray,
    segmentation: Segmentation,
    objects: list[DetectedObject],
    scale: int = 2,
    title: str | None = None,
) -> np.ndarray:
    """The frame (upscaled by `scale`) with each object's contour, centroid and labels, and the
    hand's contour; returns uint8 RGB (H*scale, W*scale, 3)."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    h, w = frame.shape[:2]
    dpi = 100
    fig = Figure(figsize=(w * scale / dpi, h * scale / dpi), dpi=dpi)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.imshow(frame, interpolation="nearest", extent=(-0.5, w - 0.5, h - 0.5, -0.5))
    ax.set_xlim(-0.5, w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)
    ax.axis("off")
    blobs = sorted(segmentation.objects, key=lambda b: b.centroid()[0])
    for obj, blob in zip(objects, blobs, strict=False):
        color = _COLORS[obj.id % len(_COLORS)]
        full = blob.full_mask(segmentation.shape).astype(float)
        ax.contour(full, levels=[0.5], colors=[color], linewidths=1.2)
        cx, cy = obj.features.centroid
        ax.plot([cx], [cy], marker="+", color=color, markersize=10, mew=1.5)
        text = [f"#{obj.id}"]
        for var in ("Color", "Shape", "Size"):
            if var in obj.labels:
                text.append(obj.labels[var])
        x0, y0 = obj.features.bbox[:2]
        ax.text(
            x0,
            max(y0 - 2, 6),
            " ".join(text),
            color="white",
            fontsize=8,
            va="bottom",
            bbox={"facecolor": "black", "alpha": 0.6, "pad": 1.5, "edgecolor": color},
        )
    if segmentation.hand is not None:
        ax.contour(
            segmentation.hand_mask.astype(float),
            levels=[0.5],
            colors=["#ffffff"],
            linewidths=1.0,
            linestyles="dashed",
        )
        hx, hy = segmentation.hand.centroid()
        ax.text(hx, hy, "hand", color="white", fontsize=8, ha="center")
    if title:
        ax.text(
            2,
            h - 3,
            title,
            color="white",
            fontsize=7,
            va="bottom",
            bbox={"facecolor": "black", "alpha": 0.5, "pad": 1.0},
        )
    canvas.draw()  # type: ignore[no-untyped-call]  # matplotlib leaves these unannotated
    rgba = np.asarray(canvas.buffer_rgba())  # type: ignore[no-untyped-call]
    return np.ascontiguousarray(rgba[:, :, :3])


def save_overlay(
    path: str | Path,
    frame: np.ndarray,
    segmentation: Segmentation,
    objects: list[DetectedObject],
    title: str | None = None,
) -> Path:
    """Write the overlay as PNG (or PPM, by suffix)."""
    from beyond_self.cognition.vision.images import write_image

    return write_image(path, render_overlay(frame, segmentation, objects, title=title))
