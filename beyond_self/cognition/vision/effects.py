"""The effects of an action, measured on tracks, then discretised by the learned clusters.

Object speed (its peak), hand speed (the approach's peak), object–hand relative speed (from just
after contact to 0.3 s after the last) and contact duration, defined as the synthetic world's
`Effects` are, so measurement and truth can agree. Pixels become metres through the camera model
before anything is differentiated (the object at the table plane, the hand at its height), so
perspective does not inflate the speed of a hand nearer the camera.
"""

from __future__ import annotations

import itertools
from dataclasses import asdict, dataclass

import numpy as np

from beyond_self.cognition.vision.clusters import ClusterModel
from beyond_self.cognition.vision.tracking import peak_speed, velocities

EFFECT_FEATURES = {
    "ObjVel": "object_speed",
    "HandVel": "hand_speed",
    "ObjHandVel": "relative_speed",
    "Contact": "contact_s",
}
POST_CONTACT_S = 0.3


@dataclass(frozen=True)
class EffectMeasures:
    """Continuous effects of one recording; hand-related ones are None without a hand."""

    object_speed: float
    hand_speed: float | None
    relative_speed: float | None
    contact_s: float | None
    contact: tuple[int, int] | None  # frames [start, end) of the longest contact

    def as_dict(self) -> dict[str, float]:
        """The measurements that exist, by feature name (what `ClusterModel.label_all` takes)."""
        d = asdict(self)
        d.pop("contact")
        return {k: float(v) for k, v in d.items() if v is not None}

    def labels(self, clusters: ClusterModel) -> dict[str, str]:
        """Discrete effect values (ObjVel, HandVel, ObjHandVel, Contact) that can be measured."""
        m = self.as_dict()
        out = {}
        for variable, feature in EFFECT_FEATURES.items():
            if feature in m and variable in clusters.variables:
                out[variable] = clusters.label(variable, m)
        return out


def contact_run(flags: np.ndarray, bridge: int = 1) -> tuple[int, int] | None:
    """The longest run of True in `flags` as [start, end), bridging gaps of ≤ `bridge` frames."""
    f = np.asarray(flags, dtype=bool).copy()
    idx = np.flatnonzero(f)
    if idx.size == 0:
        return None
    for a, b in itertools.pairwise(idx):
        if 1 < b - a <= bridge + 1:
            f[a:b] = True
    best: tuple[int, int] | None = None
    start = None
    for i, v in enumerate([*f.tolist(), False]):
        if v and start is None:
            start = i
        elif not v and start is not None:
            if best is None or i - start > best[1] - best[0]:
                best = (start, i)
            start = None
    return best


def measure_effects(
    object_frames: np.ndarray,
    object_xy: np.ndarray,
    fps: float,
    hand_frames: np.ndarray | None = None,
    hand_xy: np.ndarray | None = None,
    contact_flags: np.ndarray | None = None,
    post_s: float = POST_CONTACT_S,
) -> EffectMeasures:
    """Effects from an object track and (optionally) a hand track and per-frame contact flags
    (indexed by frame number). Positions in metres in the table plane (`Camera.table_point`, the
    hand at its own height); results in m/s and s."""
    of = np.asarray(object_frames, dtype=np.int64)
    op = np.asarray(object_xy, dtype=np.float64)
    obj_speed = peak_speed(of, op, fps)
    if hand_frames is None or hand_xy is None or len(hand_frames) < 2:
        return EffectMeasures(obj_speed, None, None, None, None)
    hf = np.asarray(hand_frames, dtype=np.int64)
    hp = np.asarray(hand_xy, dtype=np.float64)
    run = contact_run(contact_flags) if contact_flags is not None else None
    if run is None:
        # no touch seen: the closest approach stands for the contact moment
        common = np.intersect1d(of, hf)
        if common.size:
            o = op[np.searchsorted(of, common)]
            h = hp[np.searchsorted(hf, common)]
            k = int(common[np.argmin(np.linalg.norm(o - h, axis=1))])
        else:
            k = int(hf[-1])
        start, end, contact_s = k, k + 1, 0.0
    else:
        start, end = run
        contact_s = (end - start) / fps
    approach = peak_speed(hf, hp, fps, window=(int(hf[0]), start)) if start > hf[0] else 0.0
    vo = velocities(of, op, fps)
    vh = velocities(hf, hp, fps)
    # from 2 frames into the contact (the velocity estimate spans ±2 frames, and must not see the
    # approach) to post_s after it
    window = (of >= min(start + 2, end)) & (of < end + round(post_s * fps))
    rel = 0.0
    if window.any() and len(hf) >= 2:
        vhx = np.interp(of[window], hf, vh[:, 0])
        vhy = np.interp(of[window], hf, vh[:, 1])
        d = vo[window] - np.column_stack([vhx, vhy])
        rel = float(np.linalg.norm(d, axis=1).max())
    return EffectMeasures(
        object_speed=obj_speed,
        hand_speed=approach,
        relative_speed=rel,
        contact_s=contact_s,
        contact=None if run is None else run,
    )
