"""Continuous features of one segmented object: where it is, how big, what colour, what shape.

Shape descriptors are scale-, rotation- and position-invariant, so clusters learned on the
synthetic table transfer to a real camera: circularity (with a Cauchy–Crofton perimeter, nearly
unbiased at any orientation), rectangularity (the most telling of box versus round), convexity,
solidity and eccentricity; hull and rectangle are grown by half a pixel, which undoes the
shrinking of small shapes. Colour is the mean CIELAB; size the equivalent diameter in metres at
the table plane (README.md in this folder).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import cast

import numpy as np

# scipy is imported in the functions that use it: a process that only needs this module's types
# (`beyond up` checking the object segmenter's options) then does not load it (1.3 s of CPU)
from beyond_self.cognition.vision.color import rgb_to_lab
from beyond_self.cognition.vision.segmentation import Blob, Segmentation
from beyond_self.cognition.vision.tabletop import Camera

SHAPE_FEATURES = ("circularity", "rectangularity", "convexity", "solidity", "eccentricity")
FEATURE_DEFINITIONS: dict[str, str] = {
    "L": "mean CIELAB L* (lightness, 0..100) of the object's pixels",
    "a": "mean CIELAB a* (green -, red +) of the object's pixels",
    "b": "mean CIELAB b* (blue -, yellow +) of the object's pixels",
    "circularity": "4*pi*area / perimeter^2 (Cauchy-Crofton perimeter); 1 = disc",
    "rectangularity": "area / minimum-area enclosing rectangle; 1 = box, pi/4 = disc or ellipse",
    "convexity": "convex hull perimeter / perimeter; 1 = convex",
    "solidity": "area / convex hull area; 1 = convex",
    "eccentricity": "eccentricity of the same-moments ellipse; 0 = disc",
    "diameter_m": "equivalent diameter 2*sqrt(area/pi) in metres at the table plane",
    "object_speed": "peak speed of the tracked object centroid (m/s, table plane)",
    "hand_speed": "peak speed of the hand before contact (m/s, table plane)",
    "relative_speed": "peak object-minus-hand speed from contact to 0.3 s after it (m/s)",
    "contact_s": "longest run of frames with the hand within 2 px of the object (s)",
}


@dataclass(frozen=True)
class ObjectFeatures:
    """What the segmenter measured of one object in one frame."""

    centroid: tuple[float, float]  # (x, y) pixels, pixel centres on integer coordinates
    area: int  # pixels
    bbox: tuple[int, int, int, int]  # (x, y, width, height)
    lab: tuple[float, float, float]
    rgb: tuple[float, float, float]
    perimeter: float
    circularity: float
    rectangularity: float
    convexity: float
    solidity: float
    eccentricity: float
    orientation: float  # radians, major axis against the image x axis
    diameter_m: float

    def vector(self, names: tuple[str, ...] | list[str]) -> np.ndarray:
        """The named features as a vector (names from FEATURE_DEFINITIONS)."""
        values = {"L": self.lab[0], "a": self.lab[1], "b": self.lab[2]}
        return np.array([values[n] if n in values else getattr(self, n) for n in names], float)

    def to_dict(self) -> dict[str, object]:
        d = asdict(self)
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in d.items()}


# Crofton directions (dx, dy) and their angular weights (radians, summing to pi): the eight
# directions of the 5x5 neighbourhood, each weighted by the arc of angles nearest to it.
_CROFTON = ((1, 0), (2, 1), (1, 1), (1, 2), (0, 1), (-1, 2), (-1, 1), (-2, 1))


def _crofton_weights() -> np.ndarray:
    ang = np.array([np.arctan2(dy, dx) for dx, dy in _CROFTON])
    nxt = np.roll(ang, -1)
    nxt[-1] += np.pi
    prv = np.roll(ang, 1)
    prv[0] -= np.pi
    return cast(np.ndarray, (nxt - prv) / 2.0)


_CROFTON_W = _crofton_weights()


def crofton_perimeter(mask: np.ndarray) -> float:
    """Perimeter of a binary region by the Cauchy–Crofton formula on 8 line directions.

    For a direction d, the pixel pairs (p, p + d) on either side of the boundary number about
    |d| times twice the region's mean projected width in that direction; the perimeter is the
    integral of that width over directions (Cauchy). Eight directions keep the error within ~1.5%
    at any orientation (four directions: ~5%)."""
    m = np.pad(mask, 2)
    h, w = m.shape
    total = 0.0
    for (dx, dy), weight in zip(_CROFTON, _CROFTON_W, strict=True):
        a = m[max(0, -dy) : h - max(0, dy), max(0, -dx) : w - max(0, dx)]
        b = m[max(0, dy) : h - max(0, -dy), max(0, dx) : w - max(0, -dx)]
        count = np.count_nonzero(a != b)
        total += weight * count / (2.0 * np.hypot(dx, dy))
    return float(total)


def _boundary_points(mask: np.ndarray) -> np.ndarray:
    m = np.pad(mask, 1)
    inner = m[1:-1, 1:-1] & m[:-2, 1:-1] & m[2:, 1:-1] & m[1:-1, :-2] & m[1:-1, 2:]
    ys, xs = np.nonzero(mask & ~inner)
    return np.column_stack([xs, ys]).astype(np.float64)


def hull_and_rectangle(mask: np.ndarray) -> tuple[float, float, float]:
    """(hull area, hull perimeter, minimum enclosing rectangle area), each grown by half a pixel."""
    from scipy.spatial import ConvexHull, QhullError

    pts = _boundary_points(mask)
    try:
        hull = ConvexHull(pts)
    except (QhullError, ValueError):  # a line or a point: degenerate hull
        w = np.ptp(pts[:, 0]) + 1.0 if len(pts) else 1.0
        h = np.ptp(pts[:, 1]) + 1.0 if len(pts) else 1.0
        return float(w * h), float(2 * (w + h)), float(w * h)
    verts = pts[hull.vertices]
    area, perim = float(hull.volume), float(hull.area)  # 2-D: volume = area, area = perimeter
    edges = np.roll(verts, -1, axis=0) - verts
    lengths = np.linalg.norm(edges, axis=1)
    ok = lengths > 0
    e = edges[ok] / lengths[ok, None]
    n = np.column_stack([-e[:, 1], e[:, 0]])
    pu = verts @ e.T  # (V, E)
    pv = verts @ n.T
    widths = np.ptp(pu, axis=0) + 1.0
    heights = np.ptp(pv, axis=0) + 1.0
    rect = float(np.min(widths * heights))
    grown = area + perim / 2.0 + np.pi / 4.0
    return grown, perim + np.pi, rect


def measure_blob(
    frame: np.ndarray, blob: Blob, camera: Camera | None = None, lab: bool = True
) -> ObjectFeatures:
    """All features of one blob of `frame`."""
    cam = camera or Camera(width=frame.shape[1], height=frame.shape[0])
    mask = blob.mask
    ys, xs = np.nonzero(mask)
    area = int(xs.size)
    x = xs + blob.bbox[0]
    y = ys + blob.bbox[1]
    cx, cy = float(x.mean()), float(y.mean())
    pixels = frame[blob.slices][mask].astype(np.float64)
    rgb = pixels.mean(axis=0)
    mean_lab = rgb_to_lab(pixels).mean(axis=0) if lab else rgb_to_lab(rgb)
    perimeter = crofton_perimeter(mask)
    hull_area, hull_perimeter, rect_area = hull_and_rectangle(mask)
    dx, dy = x - cx, y - cy
    cov = np.array([[np.mean(dx * dx), np.mean(dx * dy)], [np.mean(dx * dy), np.mean(dy * dy)]])
    cov += np.eye(2) / 12.0  # each pixel is a unit square, not a point
    evals, evecs = np.linalg.eigh(cov)
    ecc = float(np.sqrt(max(0.0, 1.0 - evals[0] / evals[1])))
    major = evecs[:, 1]
    bx0, by0 = int(x.min()), int(y.min())
    return ObjectFeatures(
        centroid=(cx, cy),
        area=area,
        bbox=(bx0, by0, int(x.max()) - bx0 + 1, int(y.max()) - by0 + 1),
        lab=(float(mean_lab[0]), float(mean_lab[1]), float(mean_lab[2])),
        rgb=(float(rgb[0]), float(rgb[1]), float(rgb[2])),
        perimeter=perimeter,
        circularity=float(4.0 * np.pi * area / max(perimeter, 1e-9) ** 2),
        rectangularity=float(area / max(rect_area, 1.0)),
        convexity=float(min(hull_perimeter / max(perimeter, 1e-9), 1.0)),
        solidity=float(min(area / max(hull_area, 1.0), 1.0)),
        eccentricity=ecc,
        orientation=float(np.arctan2(major[1], major[0])),
        diameter_m=float(2.0 * np.sqrt(area / np.pi) / cam.px_per_m(0.0)),
    )


def measure(
    frame: np.ndarray, segmentation: Segmentation, camera: Camera | None = None
) -> list[ObjectFeatures]:
    """Features of every object blob of a segmented frame (largest first)."""
    return [measure_blob(frame, b, camera) for b in segmentation.objects]
