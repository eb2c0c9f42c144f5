"""The table model: what each pixel looks like with nothing on the table.

`BackgroundModel.fit(frames)` takes the per-pixel median of a few frames of the empty table;
`BackgroundModel.from_frame(frame)` estimates it from the frame itself (block means, a wide
median, objects masked and filled from the surrounding table), since a robot does not always see
an empty table first. A pixel is compared with it by Horprasert et al.'s (1999) brightness and
chromaticity distortion: a shadow darkens the table without changing its colour, so shadows are
told from objects here rather than by their shape (README.md in this folder).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import cast

import numpy as np

# scipy is imported in the functions that use it: a process that only needs this module's types
# (`beyond up` checking the object segmenter's options) then does not load it (1.3 s of CPU)
from beyond_self.cognition.vision.images import as_frame
from beyond_self.core.errors import InputError


@lru_cache(maxsize=16)
def _interp_matrix(n_out: int, n_in: int, block: int) -> np.ndarray:
    """Linear interpolation from block centres (block-mean grid) to every pixel, edges clamped."""
    centres = (np.arange(n_in) + 0.5) * block - 0.5
    x = np.clip(np.arange(n_out, dtype=np.float64), centres[0], centres[-1])
    i = np.clip(np.searchsorted(centres, x, side="right") - 1, 0, max(n_in - 2, 0))
    m = np.zeros((n_out, n_in), dtype=np.float32)
    if n_in == 1:
        m[:, 0] = 1.0
        return m
    w = (x - centres[i]) / (centres[i + 1] - centres[i])
    m[np.arange(n_out), i] = 1.0 - w
    m[np.arange(n_out), i + 1] = w
    return m


def upsample(small: np.ndarray, shape: tuple[int, int], block: int) -> np.ndarray:
    """Bilinear upsampling of a (h, w, 3) block grid to (H, W, 3), by two small matrix products
    (an order of magnitude faster than scipy.ndimage.zoom on this shape). The result is a view
    of three contiguous channel planes, the layout `BackgroundModel` keeps."""
    ry = _interp_matrix(shape[0], small.shape[0], block)
    rx = _interp_matrix(shape[1], small.shape[1], block)
    tmp = np.tensordot(ry, small, axes=(1, 0))  # (H, w, 3)
    out = np.matmul(tmp.transpose(2, 0, 1), rx.T)  # (3, H, W)
    return cast(np.ndarray, out.transpose(1, 2, 0))


def block_sums(frame: np.ndarray, block: int) -> np.ndarray:
    """Sum of each block×block tile of an 8-bit frame, as integers (edge tiles padded by
    replication): rows of tiles added, then columns, each over a contiguous axis (3× faster than
    `reduceat`); exact in any order."""
    h, w = frame.shape[:2]
    hb, wb = -(-h // block), -(-w // block)
    if hb * block != h or wb * block != w:
        frame = np.pad(frame, ((0, hb * block - h), (0, wb * block - w), (0, 0)), mode="edge")
    dtype = np.uint16 if block * block * 255 < 2**16 else np.uint32
    rows = frame.reshape(hb, block, wb * block * 3).sum(axis=1, dtype=dtype)
    return cast(np.ndarray, rows.reshape(hb, wb, block, 3).sum(axis=2, dtype=dtype))


def block_means(frame: np.ndarray, block: int) -> np.ndarray:
    """Mean colour of each block×block tile (edge tiles padded by replication).

    An 8-bit frame's tiles are summed as integers (`block_sums`) and divided once: the same
    float32 values, since a float32 sum of fewer than 2^24 / 255 bytes is exact in any order."""
    if frame.dtype == np.uint8 and block * block * 255 < 2**24:
        return _means(block_sums(frame, block), block)
    h, w = frame.shape[:2]
    hb, wb = -(-h // block), -(-w // block)
    if hb * block != h or wb * block != w:
        frame = np.pad(frame, ((0, hb * block - h), (0, wb * block - w), (0, 0)), mode="edge")
    img = frame.astype(np.float32)
    return cast(np.ndarray, img.reshape(hb, block, wb, block, 3).mean(axis=(1, 3)))


def _means(sums: np.ndarray, block: int) -> np.ndarray:
    return cast(np.ndarray, sums.astype(np.float32) / np.float32(block * block))


def distortions(
    frame: np.ndarray, mean: np.ndarray, mean_sq_norm: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Brightness distortion alpha and normalised chromaticity distortion of each pixel."""
    img = frame.astype(np.float32)
    bb = mean_sq_norm if mean_sq_norm is not None else _dot(mean, mean) + 1.0
    ib = _dot(img, mean)
    ii = _dot(img, img)
    alpha = ib / bb
    cd2 = np.maximum(ii - ib * alpha, 0.0) / bb
    return alpha, np.sqrt(cd2)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-pixel dot product of two (H, W, 3) arrays (3× faster than einsum here)."""
    out = a[..., 0] * b[..., 0]
    out += a[..., 1] * b[..., 1]
    out += a[..., 2] * b[..., 2]
    return cast(np.ndarray, out)


def _plane_distortions(
    frame: np.ndarray, planes: np.ndarray, bb: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """`distortions` of an (H, W, 3) frame against a table kept as (3, H, W) planes: the same
    operations in the same order on each pixel (the same values), over contiguous rows and
    into two buffers rather than a dozen arrays, which is twice as fast."""
    img = np.moveaxis(frame, 2, 0).astype(np.float32, order="C")
    ib = img[0] * planes[0]
    tmp = img[1] * planes[1]
    ib += tmp
    np.multiply(img[2], planes[2], out=tmp)
    ib += tmp
    ii = img[0] * img[0]
    np.multiply(img[1], img[1], out=tmp)
    ii += tmp
    np.multiply(img[2], img[2], out=tmp)
    ii += tmp
    alpha = ib / bb
    np.multiply(ib, alpha, out=tmp)
    np.subtract(ii, tmp, out=ii)
    np.maximum(ii, 0.0, out=ii)
    ii /= bb
    return alpha, np.sqrt(ii, out=ii)


@dataclass
class BackgroundModel:
    """Per-pixel table colour (float32 sRGB, H×W×3) and how noisy the table looks. Kept as
    three contiguous channel planes, `mean` their H×W×3 view: a frame is compared with it plane
    by plane."""

    mean: np.ndarray
    noise: float = 0.02  # typical chromaticity distortion of a table pixel (robust)
    source: str = "frame"

    def __post_init__(self) -> None:
        mean = np.asarray(self.mean, dtype=np.float32)
        self._planes = np.ascontiguousarray(np.moveaxis(mean, 2, 0))
        self.mean = np.moveaxis(self._planes, 0, 2)
        p = self._planes
        self._bb = p[0] * p[0]
        self._bb += p[1] * p[1]
        self._bb += p[2] * p[2]
        self._bb += 1.0

    @property
    def shape(self) -> tuple[int, int]:
        return int(self.mean.shape[0]), int(self.mean.shape[1])

    def compare(self, frame: np.ndarray, every: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """(alpha, chromaticity distortion) of a frame against this table; with `every` > 1,
        of every `every`-th pixel in each direction only (both are per pixel)."""
        if frame.shape[:2] != self.shape:
            raise InputError(
                f"frame is {frame.shape[1]}x{frame.shape[0]} but the background model is "
                f"{self.shape[1]}x{self.shape[0]}; valid: frames of the model's size"
            )
        if every > 1:
            grid = (slice(None, None, every), slice(None, None, every))
            return _plane_distortions(frame[grid], self._planes[:, *grid], self._bb[grid])
        return _plane_distortions(frame, self._planes, self._bb)

    @classmethod
    def fit(cls, frames: Sequence[np.ndarray] | np.ndarray) -> BackgroundModel:
        """From frames of the empty table (per-pixel median; one frame is enough)."""
        stack = [as_frame(f, name=f"background frame {i}") for i, f in enumerate(frames)]
        if not stack:
            raise InputError("no background frames given; valid: one or more empty-table frames")
        if len({f.shape for f in stack}) != 1:
            raise InputError("background frames differ in size; valid: frames of one size")
        mean = np.median(np.stack(stack).astype(np.float32), axis=0)
        model = cls(mean=mean, source=f"{len(stack)} empty frame(s)")
        model.noise = _noise(stack[0], model)
        return model

    @classmethod
    def from_frame(cls, frame: np.ndarray, block: int | None = None) -> BackgroundModel:
        """Estimate the table under and around the objects from the frame itself."""
        return cls.estimate(frame, block)[0]

    @classmethod
    def estimate(
        cls, frame: np.ndarray, block: int | None = None
    ) -> tuple[BackgroundModel, np.ndarray, np.ndarray]:
        """`from_frame`, and the frame's own (alpha, chromaticity distortion) against it: the
        table's noise is measured on those, so a segmenter of the frame need not compare the
        frame again."""
        from scipy import ndimage

        img = as_frame(frame)
        h, w = img.shape[:2]
        b = block or max(4, round(min(h, w) / 30))
        sums = block_sums(img, b)
        small = _means(sums, b)
        k = max(3, 2 * (min(small.shape[:2]) // 8) + 1)  # median window ~ a quarter of the view
        # the median of the tiles' sums, divided as their means are: the median of the means
        # (a monotone map keeps the order), found among integers, which is faster
        first = _means(median_window(sums, k), b)
        alpha, cd = distortions(small, first)
        outlier = (cd > 0.03) | (np.abs(alpha - 1.0) > 0.06)
        outlier = ndimage.binary_dilation(outlier, iterations=1)
        keep = (~outlier).astype(np.float32)
        sigma = max(1.0, k / 3.0)
        num = ndimage.gaussian_filter(small * keep[:, :, None], sigma=(sigma, sigma, 0))
        den = ndimage.gaussian_filter(keep, sigma=sigma)[:, :, None]
        filled = np.where(den > 1e-3, num / np.maximum(den, 1e-6), first)
        table = np.where(outlier[:, :, None], filled, small)
        model = cls(mean=upsample(table, (h, w), b), source="estimated from the frame")
        alpha, cd = model.compare(img)
        # every third pixel each way, as `_noise` takes them: the distortions are per pixel
        model.noise = _spread(cd[::_NOISE_EVERY, ::_NOISE_EVERY])
        return model, alpha, cd


def median_window(grid: np.ndarray, k: int) -> np.ndarray:
    """Per channel, the median of each k×k window (k odd) of an (h, w, 3) grid of any dtype,
    edges replicated: scipy.ndimage.median_filter(grid, size=(k, k, 1), mode="nearest"), value
    for value (the median of an odd count is one of the values). Its generic rank filter took a
    sixth of a frame's description; one partition over the stacked windows takes a fraction."""
    r = k // 2
    padded = np.pad(grid, ((r, r), (r, r), (0, 0)), mode="edge")
    windows = np.lib.stride_tricks.sliding_window_view(padded, (k, k), axis=(0, 1))
    stacked = windows.reshape(*grid.shape, k * k)  # (h, w, 3, k²): a copy, partitioned in place
    stacked.partition(k * k // 2, axis=-1)
    return np.ascontiguousarray(stacked[..., k * k // 2])


_NOISE_EVERY = 3  # the noise is measured on every third pixel in each direction


def _noise(frame: np.ndarray, model: BackgroundModel) -> float:
    """Robust spread of the chromaticity distortion on a subsample, the distortion computed on
    the subsample's pixels only."""
    return _spread(model.compare(frame, every=_NOISE_EVERY)[1])


def _spread(cd: np.ndarray) -> float:
    """Median + 1.4826·MAD of the chromaticity distortions `cd`."""
    sample = cd.ravel()
    med = float(np.median(sample))
    return med + 1.4826 * float(np.median(np.abs(sample - med)))
