"""Shape and size descriptors on shapes whose true values are known analytically."""

from __future__ import annotations

import numpy as np
import pytest

from beyond_self.cognition.vision.features import (
    crofton_perimeter,
    hull_and_rectangle,
    measure_blob,
)
from beyond_self.cognition.vision.segmentation import Blob
from beyond_self.cognition.vision.tabletop import Camera

YY, XX = np.mgrid[0:120, 0:120].astype(float)


def disc(r: float, cx: float = 60.3, cy: float = 59.6) -> np.ndarray:
    return (XX - cx) ** 2 + (YY - cy) ** 2 < r * r


def rect(a: float, b: float, deg: float) -> np.ndarray:
    t = np.radians(deg)
    dx, dy = XX - 60.2, YY - 59.7
    u = dx * np.cos(t) + dy * np.sin(t)
    v = -dx * np.sin(t) + dy * np.cos(t)
    return (np.abs(u) < a / 2) & (np.abs(v) < b / 2)


def features(mask: np.ndarray) -> object:
    frame = np.zeros((*mask.shape, 3), np.uint8)
    frame[mask] = (200, 40, 40)
    return measure_blob(frame, Blob((0, 0, mask.shape[1], mask.shape[0]), mask), Camera())


@pytest.mark.parametrize("r", [8.0, 15.0, 30.0])
def test_crofton_perimeter_of_discs_is_close_to_two_pi_r(r: float) -> None:
    assert crofton_perimeter(disc(r)) == pytest.approx(2 * np.pi * r, rel=0.03)


@pytest.mark.parametrize("deg", [0.0, 20.0, 45.0])
def test_perimeter_of_rotated_rectangle(deg: float) -> None:
    assert crofton_perimeter(rect(40, 24, deg)) == pytest.approx(2 * (40 + 24), rel=0.04)


def test_disc_descriptors() -> None:
    f = features(disc(20))
    assert f.circularity == pytest.approx(1.0, abs=0.03)
    assert f.rectangularity == pytest.approx(np.pi / 4, abs=0.02)
    assert f.eccentricity < 0.15
    assert f.solidity > 0.97 and f.convexity > 0.98
    assert f.centroid == pytest.approx((60.3, 59.6), abs=0.05)
    # equivalent diameter: 40 px at 320 px/m
    assert f.diameter_m == pytest.approx(40 / 320, rel=0.01)


@pytest.mark.parametrize("deg", [0.0, 30.0])
def test_box_descriptors(deg: float) -> None:
    f = features(rect(48, 30, deg))
    assert f.rectangularity > 0.9
    # circularity of a 48x30 rectangle: 4*pi*A/P^2
    assert f.circularity == pytest.approx(4 * np.pi * 48 * 30 / (2 * 78) ** 2, abs=0.04)
    # eccentricity of the same-moments ellipse: sqrt(1 - (30/48)^2)
    assert f.eccentricity == pytest.approx(np.sqrt(1 - (30 / 48) ** 2), abs=0.03)
    assert abs(np.cos(f.orientation)) == pytest.approx(np.cos(np.radians(deg)), abs=0.02)


def test_non_convex_shape_has_low_solidity() -> None:
    ring_l = rect(60, 60, 0) & ~((XX > 60) & (YY < 60))  # an L: three quarters of a square
    area, _, rect_area = hull_and_rectangle(ring_l)
    f = features(ring_l)
    assert f.solidity < 0.9 and f.convexity < 0.95
    assert rect_area == pytest.approx(60 * 60, rel=0.05)
    assert area == pytest.approx(60 * 60 - 30 * 30 / 2, rel=0.03)  # the square minus a triangle


def test_mean_colour_is_cielab_of_the_pixels() -> None:
    f = features(disc(10))
    assert f.rgb == pytest.approx((200.0, 40.0, 40.0))
    assert f.lab[1] > 40 and f.lab[2] > 20  # a red: a* and b* positive
