"""From a frame to object blobs (and the hand's blob): foreground, shadows, components.

A pixel is a candidate when its colour differs from the table model's or it is darker or
brighter than any shadow or highlight (a shadow only darkens, so it is not one); skin-coloured
candidates are the hand, kept apart so a hand touching an object does not merge with it; the rest
are opened and labelled; each component keeps the pixels closer to its own core colour than to
the table (trimming coloured shadows a global threshold cannot); too small, too thin or
border-cut components are dropped. The steps' reasons are in README.md in this folder.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import cast

import numpy as np

# scipy is imported in the functions that use it: a process that only needs this module's types
# (`beyond up` checking the object segmenter's options) then does not load it (1.3 s of CPU)
from beyond_self.cognition.vision.background import BackgroundModel
from beyond_self.cognition.vision.images import as_frame
from beyond_self.core.errors import InputError

_OPEN = np.ones((3, 3), dtype=bool)
_EIGHT = np.ones((3, 3), dtype=bool)


@dataclass(frozen=True)
class SkinModel:
    """Skin as an ellipse in normalised chromaticity (r, g) = (R, G) / (R + G + B).

    Chromaticity, not RGB, so the shading of a hand does not matter. The default region covers
    light-to-medium skin under white light and the synthetic hand, and stays clear of saturated
    orange, pink, yellow and green objects (a pink sponge is r ≈ 0.53, g ≈ 0.24; skin
    r ≈ 0.42, g ≈ 0.32)."""

    r: float = 0.42
    g: float = 0.315
    radius_r: float = 0.05
    radius_g: float = 0.03
    min_brightness: float = 150.0  # R + G + B; very dark pixels have unreliable chromaticity

    def mask(self, pixels: np.ndarray) -> np.ndarray:
        s = pixels.sum(axis=-1, dtype=np.float32)
        safe = np.maximum(s, 1.0)
        r = pixels[..., 0] / safe
        g = pixels[..., 1] / safe
        d = ((r - self.r) / self.radius_r) ** 2 + ((g - self.g) / self.radius_g) ** 2
        return cast(np.ndarray, (d <= 1.0) & (s >= self.min_brightness))


@dataclass(frozen=True)
class SegmentParams:
    """Thresholds of the segmenter; sizes are fractions of the image so they hold at any size."""

    chroma_low: float = 0.07
    chroma_core: float = 0.14
    dark: float = 0.5
    bright: float = 1.5
    min_area_frac: float = 1.0 / 1600.0  # 48 px at 320×240
    min_thickness_frac: float = 1.0 / 120.0  # inscribed-disc radius, 2 px at 320×240
    min_hand_area_frac: float = 1.0 / 300.0  # a hand is big: 256 px at 320×240
    min_hand_thickness_frac: float = 1.0 / 45.0  # and thick: inscribed radius ≥ 7 px at 320×240
    drop_border: bool = True
    refine: bool = True
    skin: SkinModel | None = field(default_factory=SkinModel)

    def min_area(self, shape: tuple[int, int]) -> int:
        return max(4, round(shape[0] * shape[1] * self.min_area_frac))


@dataclass
class Blob:
    """One connected region: its bounding box (x0, y0, x1, y1; x1, y1 exclusive) and the mask
    inside the box."""

    bbox: tuple[int, int, int, int]
    mask: np.ndarray
    touches_border: bool = False

    @property
    def area(self) -> int:
        return int(self.mask.sum())

    @property
    def slices(self) -> tuple[slice, slice]:
        x0, y0, x1, y1 = self.bbox
        return slice(y0, y1), slice(x0, x1)

    def coords(self) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (x, y) of the blob, in the full image."""
        ys, xs = np.nonzero(self.mask)
        return xs + self.bbox[0], ys + self.bbox[1]

    def centroid(self) -> tuple[float, float]:
        xs, ys = self.coords()
        return float(xs.mean()), float(ys.mean())

    def full_mask(self, shape: tuple[int, int]) -> np.ndarray:
        out = np.zeros(shape, dtype=bool)
        out[self.slices] = self.mask
        return out


@dataclass
class Segmentation:
    """Result for one frame: object blobs (largest first), the hand blob, the masks."""

    shape: tuple[int, int]
    objects: list[Blob]
    hand: Blob | None
    foreground: np.ndarray  # objects only
    hand_mask: np.ndarray
    candidates: np.ndarray  # everything that differed from the table before the object tests
    background: BackgroundModel

    def touching(self, obj: Blob, gap_px: int = 2) -> bool:
        """Whether the hand is within `gap_px` pixels of the object (contact)."""
        from scipy import ndimage

        if self.hand is None:
            return False
        x0, y0, x1, y1 = obj.bbox
        g = gap_px
        ys, xs = slice(max(y0 - g, 0), y1 + g), slice(max(x0 - g, 0), x1 + g)
        hand = self.hand_mask[ys, xs]
        if not hand.any():
            return False
        near = ndimage.binary_dilation(hand, structure=_EIGHT, iterations=g)
        local = np.zeros_like(hand)
        local[y0 - ys.start : y1 - ys.start, x0 - xs.start : x1 - xs.start] = obj.mask
        return bool((near & local).any())


def _open(mask: np.ndarray) -> np.ndarray:
    """Opening by reconstruction: removes specks and threads thinner than 3 px but, unlike a plain
    opening, gives back the corners of what remains (a rotated box keeps its sharp corners)."""
    from scipy import ndimage

    opened = ndimage.binary_opening(mask, structure=_OPEN)
    if not opened.any():
        return cast(np.ndarray, opened)
    return cast(np.ndarray, ndimage.binary_propagation(opened, structure=_EIGHT, mask=mask))


def _components(mask: np.ndarray) -> tuple[np.ndarray, list[tuple[slice, slice]]]:
    from scipy import ndimage

    labels, n = ndimage.label(mask, structure=_EIGHT)
    return labels, [s for s in ndimage.find_objects(labels) if s is not None] if n else []


def _blob(
    labels: np.ndarray,
    index: int,
    sl: tuple[slice, slice],
    shape: tuple[int, int],
    at: tuple[int, int] = (0, 0),
) -> Blob:
    """Component `index` of `labels`, which cover the image from row, column `at` on."""
    ys, xs = sl
    mask = labels[sl] == index
    y0, x0, y1, x1 = ys.start + at[0], xs.start + at[1], ys.stop + at[0], xs.stop + at[1]
    border = y0 == 0 or x0 == 0 or y1 == shape[0] or x1 == shape[1]
    return Blob((x0, y0, x1, y1), mask, border)


def _around(pads: list[tuple[slice, slice]]) -> tuple[slice, slice]:
    """The box around every one of `pads`: what is labelled again after the first labelling
    (labelling a box gives the components and the order of the whole frame's, at a fraction of
    the cost)."""
    return (
        slice(min(p[0].start for p in pads), max(p[0].stop for p in pads)),
        slice(min(p[1].start for p in pads), max(p[1].stop for p in pads)),
    )


def _within(pad: tuple[slice, slice], box: tuple[slice, slice]) -> tuple[slice, slice]:
    ys, xs = pad
    return (
        slice(ys.start - box[0].start, ys.stop - box[0].start),
        slice(xs.start - box[1].start, xs.stop - box[1].start),
    )


def _chromaticity(pixels: np.ndarray) -> np.ndarray:
    s = np.maximum(pixels.sum(axis=-1, keepdims=True, dtype=np.float32), 1.0)
    return cast(np.ndarray, (pixels[..., :2] / s).astype(np.float32))


def segment(
    frame: np.ndarray,
    background: BackgroundModel | None = None,
    params: SegmentParams | None = None,
    hand_px: tuple[float, float] | None = None,
) -> Segmentation:
    """Segment one RGB frame into object blobs and a hand blob.

    `background`: the table model (estimated from this frame when None). `hand_px`: where the
    skeleton says the hand is (pixels); the hand blob is then the skin region nearest to it."""
    from scipy import ndimage

    p = params or SegmentParams()
    img = as_frame(frame)
    shape = (int(img.shape[0]), int(img.shape[1]))
    if shape[0] < 16 or shape[1] < 16:
        raise InputError(f"frame is {shape[1]}x{shape[0]} pixels; valid: at least 16x16")
    if int(img.max()) - int(img.min()) < 3:
        raise InputError("frame is blank (every pixel has the same colour); valid: a camera image")
    if background is None:
        bg, alpha, cd = BackgroundModel.estimate(img)
    else:
        bg = background
        alpha, cd = bg.compare(img)
    low = max(p.chroma_low, 3.0 * bg.noise)
    strong = (alpha < p.dark) | (alpha > p.bright)
    cand = (cd > low) | strong
    min_area = p.min_area(shape)
    labels, slices = _components(cand)
    regions = []  # (slice padded by 1, mask of the component inside it)
    for i, sl in enumerate(slices, start=1):
        ys, xs = sl
        if (ys.stop - ys.start) * (xs.stop - xs.start) < min_area // 2:
            continue
        pad = (
            slice(max(ys.start - 1, 0), min(ys.stop + 1, shape[0])),
            slice(max(xs.start - 1, 0), min(xs.stop + 1, shape[1])),
        )
        comp = labels[pad] == i
        if comp.sum() >= min_area // 2:
            regions.append((pad, comp))

    hand_mask = np.zeros(shape, dtype=bool)
    hand_blob: Blob | None = None
    if not regions:
        return Segmentation(shape, [], None, np.zeros(shape, dtype=bool), hand_mask, cand, bg)
    box = _around([pad for pad, _ in regions])  # every region: all that is labelled from here
    at = (box[0].start, box[1].start)
    if p.skin is not None:
        skinned = False
        for pad, comp in regions:
            skin = comp & p.skin.mask(img[pad].astype(np.float32))
            if skin.sum() >= min_area:
                hand_mask[pad] |= _open(skin)
                skinned = True
        if skinned:
            hand_blob = _pick_hand(hand_mask[box], shape, hand_px, p, at)
            hand_mask[box] = False
        if hand_blob is not None:
            hand_mask[hand_blob.slices] = hand_blob.mask

    kept = np.zeros((box[0].stop - box[0].start, box[1].stop - box[1].start), dtype=bool)
    core_thr = max(p.chroma_core, 2.0 * low)
    for pad, comp in regions:
        mask = comp & ~hand_mask[pad] if hand_blob is not None else comp
        mask = _open(mask)
        if mask.sum() < min_area:
            continue
        core = mask & ((cd[pad] > core_thr) | strong[pad])
        if core.sum() < max(min_area // 4, 4):
            continue  # a faint region: shadow edge, table texture
        if p.refine:
            mask = _refine(img[pad], bg.mean[pad], mask, core, strong[pad])
        kept[_within(pad, box)] |= mask
    objects: list[Blob] = []
    if kept.any():
        labels, slices = _components(kept)
        thick = max(1.0, shape[1] * p.min_thickness_frac)
        for i, sl in enumerate(slices, start=1):
            blob = _blob(labels, i, sl, shape, at)
            if blob.area < min_area or (p.drop_border and blob.touches_border):
                continue
            blob.mask = ndimage.binary_fill_holes(blob.mask)
            if _thickness(blob.mask) < thick:
                continue
            objects.append(blob)
    objects.sort(key=lambda b: -b.area)
    foreground = np.zeros(shape, dtype=bool)
    for blob in objects:
        foreground[blob.slices] |= blob.mask
    return Segmentation(shape, objects, hand_blob, foreground, hand_mask, cand, bg)


def _pick_hand(
    hand_mask: np.ndarray,
    shape: tuple[int, int],
    hand_px: tuple[float, float] | None,
    p: SegmentParams,
    at: tuple[int, int] = (0, 0),
) -> Blob | None:
    """The hand among the skin components of `hand_mask`, which covers the image of `shape`
    from row, column `at` on."""
    labels, slices = _components(hand_mask)
    min_area = max(p.min_area(shape), round(shape[0] * shape[1] * p.min_hand_area_frac))
    thick = shape[1] * p.min_hand_thickness_frac
    best: tuple[float, Blob] | None = None
    for i, sl in enumerate(slices, start=1):
        blob = _blob(labels, i, sl, shape, at)
        area = blob.area
        if area < min_area or _thickness(blob.mask) < thick:
            continue
        if hand_px is None:
            score = -float(area)
        else:
            cx, cy = blob.centroid()
            score = float(np.hypot(cx - hand_px[0], cy - hand_px[1]))
        if best is None or score < best[0]:
            best = (score, blob)
    return None if best is None else best[1]


def _refine(
    pixels: np.ndarray, table: np.ndarray, mask: np.ndarray, core: np.ndarray, strong: np.ndarray
) -> np.ndarray:
    """Keep the pixels of `mask` whose chromaticity is nearer the core's than the table's."""
    from scipy import ndimage

    if (core & ~strong).sum() < 4:
        return mask  # dark/bright object: chromaticity says nothing useful
    chroma = _chromaticity(pixels.astype(np.float32))
    obj = np.median(chroma[core & ~strong], axis=0)
    tab = _chromaticity(table)
    d_obj = np.sum((chroma - obj) ** 2, axis=-1)
    d_tab = np.sum((chroma - tab) ** 2, axis=-1)
    out = mask & ((d_obj < d_tab) | strong)
    out = _open(out)
    if not out.any():
        return out
    labels, n = ndimage.label(out, structure=_EIGHT)
    if n > 1:  # the object is the piece holding most of the core
        counts = np.bincount(labels[core], minlength=n + 1)
        counts[0] = 0
        sizes = np.bincount(labels.ravel(), minlength=n + 1)
        keep = (counts > 0) & (sizes >= max(4, int(0.1 * sizes[1:].max())))
        keep[0] = False
        out = keep[labels]
    return cast(np.ndarray, out)


def _thickness(mask: np.ndarray) -> float:
    """Radius of the largest disc inside the mask (px)."""
    from scipy import ndimage

    padded = np.pad(mask, 1)
    return float(ndimage.distance_transform_cdt(padded, metric="chessboard").max())
