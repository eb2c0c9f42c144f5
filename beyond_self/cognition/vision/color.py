"""sRGB ↔ CIELAB (D65), the perceptual space object colours are measured and clustered in.

Why CIELAB: Euclidean distance there is roughly perceived colour difference (ΔE), so k-means on
mean object colours groups what a person would call the same colour, and its L* axis separates
brightness (shading, shadows) from hue and chroma (a*, b*).
"""

from __future__ import annotations

from typing import cast

import numpy as np

# sRGB (linear) -> XYZ, D65 white, IEC 61966-2-1.
_RGB_TO_XYZ = np.array(
    [
        [0.4124564, 0.3575761, 0.1804375],
        [0.2126729, 0.7151522, 0.0721750],
        [0.0193339, 0.1191920, 0.9503041],
    ]
)
_WHITE = np.array([0.95047, 1.0, 1.08883])
_EPS = (6.0 / 29.0) ** 3
_KAPPA = 1.0 / (3.0 * (6.0 / 29.0) ** 2)


def srgb_to_linear(rgb: np.ndarray) -> np.ndarray:
    """sRGB in [0, 255] (any shape ending in 3) -> linear RGB in [0, 1]."""
    c = np.asarray(rgb, dtype=np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(lin: np.ndarray) -> np.ndarray:
    """Linear RGB in [0, 1] -> sRGB in [0, 255] (float, unclipped)."""
    c = np.clip(np.asarray(lin, dtype=np.float64), 0.0, None)
    return 255.0 * np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1.0 / 2.4) - 0.055)


def rgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    """sRGB in [0, 255] (shape (..., 3)) -> CIELAB (L* in [0, 100], a*, b*)."""
    xyz = srgb_to_linear(rgb) @ _RGB_TO_XYZ.T / _WHITE
    f = np.where(xyz > _EPS, np.cbrt(xyz), xyz * _KAPPA + 4.0 / 29.0)
    lab = np.empty_like(f)
    lab[..., 0] = 116.0 * f[..., 1] - 16.0
    lab[..., 1] = 500.0 * (f[..., 0] - f[..., 1])
    lab[..., 2] = 200.0 * (f[..., 1] - f[..., 2])
    return cast(np.ndarray, lab)


def lab_to_rgb(lab: np.ndarray) -> np.ndarray:
    """CIELAB -> sRGB in [0, 255] (float, clipped to the gamut box)."""
    lab = np.asarray(lab, dtype=np.float64)
    fy = (lab[..., 0] + 16.0) / 116.0
    f = np.stack([fy + lab[..., 1] / 500.0, fy, fy - lab[..., 2] / 200.0], axis=-1)
    xyz = np.where(f > 6.0 / 29.0, f**3, (f - 4.0 / 29.0) / _KAPPA) * _WHITE
    lin = xyz @ np.linalg.inv(_RGB_TO_XYZ).T
    return cast(np.ndarray, np.clip(linear_to_srgb(lin), 0.0, 255.0))
