"""Frames in, affordance variables out: the vision pipeline end to end.

`describe_frame` does one still frame (objects, features, labels). `analyse_frames` does a
recording of one action: the table model from the first frame, segmentation of every frame,
nearest-centroid tracking, the object's features from the first frame, the hand from the skeleton
projected into the image (or the hand blob when there is no skeleton), contact from the masks,
then the effects. `learn_clusters` is the robot's preliminary exploration: it runs
`analyse_frames` on simulated experiments and learns every discretiser from the measurements.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from beyond_self.cognition.variables import OBJECT_FEATURES
from beyond_self.cognition.vision.background import BackgroundModel
from beyond_self.cognition.vision.clusters import VARIABLE_FEATURES, ClusterModel, learn_discretiser
from beyond_self.cognition.vision.effects import EffectMeasures, measure_effects
from beyond_self.cognition.vision.features import ObjectFeatures, measure_blob
from beyond_self.cognition.vision.images import as_frame
from beyond_self.cognition.vision.segmentation import Segmentation, SegmentParams, segment
from beyond_self.cognition.vision.tabletop import Camera, Experiment
from beyond_self.cognition.vision.tracking import Tracker
from beyond_self.core.errors import InputError

ASSUMED_HAND_HEIGHT_M = 0.05  # a hand seen only as a blob is taken to hover this high


@dataclass
class DetectedObject:
    """One object of a frame: its features and its discrete labels."""

    id: int
    features: ObjectFeatures
    labels: dict[str, str]
    distributions: dict[str, dict[str, float]] = field(default_factory=dict)

    def to_json(self) -> dict[str, object]:
        f = self.features
        d: dict[str, object] = {
            "id": self.id,
            "centroid": [round(f.centroid[0], 2), round(f.centroid[1], 2)],
            "area": f.area,
            "bbox": list(f.bbox),
        }
        for var in OBJECT_FEATURES:
            if var in self.labels:
                d[var.lower()] = self.labels[var]
        d["features"] = {
            "lab": [round(x, 2) for x in f.lab],
            "circularity": round(f.circularity, 4),
            "rectangularity": round(f.rectangularity, 4),
            "convexity": round(f.convexity, 4),
            "solidity": round(f.solidity, 4),
            "eccentricity": round(f.eccentricity, 4),
            "diameter_m": round(f.diameter_m, 4),
        }
        if self.distributions:
            d["distributions"] = {
                k.lower(): {n: round(p, 4) for n, p in v.items()}
                for k, v in self.distributions.items()
            }
        return d


def object_measurements(f: ObjectFeatures) -> dict[str, float]:
    """Named measurements of an object, as the clusters file names them."""
    return {
        "L": f.lab[0],
        "a": f.lab[1],
        "b": f.lab[2],
        "circularity": f.circularity,
        "rectangularity": f.rectangularity,
        "convexity": f.convexity,
        "solidity": f.solidity,
        "eccentricity": f.eccentricity,
        "diameter_m": f.diameter_m,
    }


def label_object(
    f: ObjectFeatures, clusters: ClusterModel
) -> tuple[dict[str, str], dict[str, dict[str, float]]]:
    """Color, Shape, Size of one object (as far as the clusters know them) and their soft
    versions."""
    m = object_measurements(f)
    labels, dists = {}, {}
    for var in OBJECT_FEATURES:
        if var in clusters.variables:
            disc = clusters.variables[var]
            x = np.asarray([m[k] for k in disc.features])
            labels[var] = disc.label(x)
            dists[var] = disc.distribution(x)
    return labels, dists


@dataclass
class FrameResult:
    segmentation: Segmentation
    objects: list[DetectedObject]


def describe_frame(
    frame: np.ndarray,
    clusters: ClusterModel | None = None,
    background: BackgroundModel | None = None,
    camera: Camera | None = None,
    params: SegmentParams | None = None,
    require_objects: bool = True,
) -> FrameResult:
    """Segment one frame and label its objects (left to right ids)."""
    img = as_frame(frame)
    seg = segment(img, background, params)
    if require_objects and not seg.objects:
        raise InputError(
            "no objects found on the table (nothing differs enough from the table colour); "
            "valid: a tabletop frame with at least one object fully in view"
        )
    cam = camera or Camera(width=img.shape[1], height=img.shape[0])
    blobs = sorted(seg.objects, key=lambda b: b.centroid()[0])
    objects = []
    for i, blob in enumerate(blobs):
        f = measure_blob(img, blob, cam)
        labels, dists = label_object(f, clusters) if clusters else ({}, {})
        objects.append(DetectedObject(i, f, labels, dists))
    return FrameResult(seg, objects)


@dataclass
class RecordingAnalysis:
    """What the robot saw in one recording of one action on one object."""

    features: ObjectFeatures  # of the acted-on object, in the first frame
    effects: EffectMeasures
    labels: dict[str, str]  # Color, Shape, Size and the measurable effects
    object_track: tuple[np.ndarray, np.ndarray]  # frames, pixel centroids
    hand_track: tuple[np.ndarray, np.ndarray]  # frames, pixel positions
    contact_flags: np.ndarray
    n_objects: int


class RecordingAnalyser:
    """`analyse_frames` one frame at a time, for a service that sees frames as they arrive: the
    per-frame work (segmentation, tracking, contact) happens in `push`, so `finish` at the end of
    a gesture only summarises. The table model comes from the first frame pushed unless given."""

    def __init__(
        self,
        fps: float,
        clusters: ClusterModel | None = None,
        camera: Camera | None = None,
        background: BackgroundModel | None = None,
        params: SegmentParams | None = None,
        gate_px: float | None = None,
    ) -> None:
        if fps <= 0:
            raise InputError(f"fps {fps} must be positive")
        self.fps = fps
        self.clusters = clusters
        self.camera = camera
        self.background = background
        self.params = params
        self.gate_px = gate_px
        self.frames = 0
        self._shape: tuple[int, ...] | None = None
        self._tracker: Tracker | None = None
        self._hand_frames: list[int] = []
        self._hand_pos: list[tuple[float, float]] = []
        self._hand_heights: list[float] = []
        self._touching: dict[int, list[int]] = {}
        self._first_blobs: dict[int, ObjectFeatures] = {}

    def push(
        self,
        frame: np.ndarray,
        hand_px: tuple[float, float] | None = None,
        hand_height_m: float = ASSUMED_HAND_HEIGHT_M,
    ) -> None:
        """Add the next frame; `hand_px` from the skeleton if known, else the hand blob is used."""
        k = self.frames
        img = as_frame(frame, name=f"frame {k}")
        if self._shape is None:
            self._shape = img.shape
            self.camera = self.camera or Camera(width=img.shape[1], height=img.shape[0])
            self.background = self.background or BackgroundModel.from_frame(img)
            gate = self.gate_px or 0.08 * self.camera.width
            self._tracker = Tracker(gate_px=gate, max_missed=int(self.fps // 3))
        elif img.shape != self._shape:
            raise InputError(
                f"frame {k} is {img.shape[1]}x{img.shape[0]}, "
                f"frame 0 {self._shape[1]}x{self._shape[0]}"
            )
        if not np.isfinite(hand_height_m):
            raise InputError(f"hand height of frame {k} is not finite")
        assert self._tracker is not None and self.camera is not None
        seg = segment(img, self.background, self.params, hand_px=hand_px)
        cents = [b.centroid() for b in seg.objects]
        ids = self._tracker.update(k, cents, [b.area for b in seg.objects])
        for tid, blob in zip(ids, seg.objects, strict=True):
            if k == 0:
                self._first_blobs[tid] = measure_blob(img, blob, self.camera)
            if seg.touching(blob):
                self._touching.setdefault(tid, []).append(k)
        hand = hand_px if hand_px is not None else (seg.hand.centroid() if seg.hand else None)
        if hand is not None:
            self._hand_frames.append(k)
            self._hand_pos.append(hand)
            self._hand_heights.append(hand_height_m)
        self.frames += 1

    def finish(self, frames: int | None = None) -> RecordingAnalysis:
        """Which object was acted on, its features, the effects, over the first `frames` frames
        pushed (all by default): everything per frame is causal, so analysing a prefix gives what
        `analyse_frames` on those frames alone gives, whatever was pushed after them."""
        n = self.frames if frames is None else min(frames, self.frames)
        if n <= 0:
            raise InputError("the recording has no frames; valid: one or more camera frames")
        if not self._first_blobs:
            raise InputError("no objects found in the first frame of the recording")
        assert self._tracker is not None and self.camera is not None
        first = self._first_blobs
        touching = {t: [k for k in ks if k < n] for t, ks in self._touching.items()}
        # the acted-on object: the first-frame object touched longest, else the biggest
        target = max(first, key=lambda t: (len(touching.get(t, [])), first[t].area))
        of, op = self._tracker.track(target).as_arrays()
        op = op[of < n]
        of = of[of < n]
        flags = np.zeros(n, dtype=bool)
        flags[touching.get(target, [])] = True
        hand_kept = [i for i, k in enumerate(self._hand_frames) if k < n]
        hf = np.asarray([self._hand_frames[i] for i in hand_kept], dtype=np.int64)
        hpos = np.asarray([self._hand_pos[i] for i in hand_kept], dtype=np.float64).reshape(-1, 2)
        obj_m = self.camera.table_point(op, 0.0)
        heights = np.asarray([self._hand_heights[i] for i in hand_kept], dtype=np.float64)
        hand_m = self.camera.table_point(hpos, heights) if len(hf) else hpos
        eff = measure_effects(of, obj_m, self.fps, hf, hand_m, flags)
        labels: dict[str, str] = {}
        if self.clusters is not None:
            labels.update(label_object(first[target], self.clusters)[0])
            labels.update(eff.labels(self.clusters))
        return RecordingAnalysis(
            features=first[target],
            effects=eff,
            labels=labels,
            object_track=(of, op),
            hand_track=(hf, hpos),
            contact_flags=flags,
            n_objects=len(first),
        )


def analyse_frames(
    frames: Sequence[np.ndarray] | np.ndarray,
    fps: float,
    clusters: ClusterModel | None = None,
    hand_px: np.ndarray | None = None,
    camera: Camera | None = None,
    background: BackgroundModel | None = None,
    params: SegmentParams | None = None,
    gate_px: float | None = None,
    hand_height_m: np.ndarray | float = ASSUMED_HAND_HEIGHT_M,
) -> RecordingAnalysis:
    """Analyse a recording: which object was acted on, its features, the effects.

    `hand_px`: (N, 2) pixel positions of the hand per frame from the skeleton stream (NaN rows
    where it was not tracked); without it the hand blob's centroid is used. `hand_height_m`: the
    hand's height above the table per frame (from the skeleton) or one assumed value, to turn
    its pixels into metres."""
    if len(frames) == 0:
        raise InputError("the recording has no frames; valid: one or more camera frames")
    if hand_px is not None and len(hand_px) != len(frames):
        raise InputError(f"hand_px has {len(hand_px)} rows for {len(frames)} frames")
    heights = np.asarray(hand_height_m, dtype=np.float64)
    if heights.ndim == 0:
        heights = np.full(len(frames), float(heights))
    if heights.shape != (len(frames),) or not np.all(np.isfinite(heights)):
        raise InputError(f"hand_height_m must be one number or {len(frames)} finite values")
    analyser = RecordingAnalyser(fps, clusters, camera, background, params, gate_px)
    for k, frame in enumerate(frames):
        hp = None
        if hand_px is not None and np.all(np.isfinite(hand_px[k])):
            hp = (float(hand_px[k][0]), float(hand_px[k][1]))
        analyser.push(frame, hp, float(heights[k]))
    return analyser.finish()


def analyse_experiment(
    exp: Experiment, clusters: ClusterModel | None = None, use_skeleton: bool = True
) -> RecordingAnalysis:
    """`analyse_frames` on a simulated experiment, with the skeleton's hand if `use_skeleton`."""
    return analyse_frames(
        exp.frames,
        exp.fps,
        clusters,
        hand_px=exp.hand_px if use_skeleton else None,
        camera=exp.camera,
        hand_height_m=exp.hand_xyz[:, 2] if use_skeleton else ASSUMED_HAND_HEIGHT_M,
    )


def measurements(a: RecordingAnalysis) -> dict[str, float]:
    """All named measurements of an analysis (object features and effects)."""
    return {**object_measurements(a.features), **a.effects.as_dict()}


def learn_clusters(
    experiments: Iterable[Experiment],
    seed: int = 0,
    progress: Callable[[int], None] | None = None,
    created_by: str = "",
) -> tuple[ClusterModel, list[dict[str, float]], list[dict[str, str]]]:
    """Learn every discretiser from exploration experiments; returns the model and the
    per-experiment measurements and ground truth it was learned from."""
    rows: list[dict[str, float]] = []
    truth: list[dict[str, str]] = []
    camera: Camera | None = None
    fps = 0.0
    for i, exp in enumerate(experiments):
        a = analyse_experiment(exp)
        rows.append(measurements(a))
        truth.append(dict(exp.labels))
        camera, fps = exp.camera, exp.fps
        if progress:
            progress(i + 1)
    if not rows or camera is None:
        raise InputError("no exploration experiments to learn clusters from")
    variables = {}
    agreement = {}
    for offset, (var, (feats, _, _)) in enumerate(VARIABLE_FEATURES.items()):
        ok = [i for i, r in enumerate(rows) if all(f in r for f in feats)]
        x = np.array([[rows[i][f] for f in feats] for i in ok])
        t = [truth[i][var] for i in ok]
        disc = learn_discretiser(var, x, t, seed=seed + offset)
        variables[var] = disc
        agreement[var] = round(
            float(np.mean([a == b for a, b in zip(disc.labels(x), t, strict=True)])), 4
        )
    model = ClusterModel(
        variables=variables,
        camera={
            "width": camera.width,
            "height": camera.height,
            "elevation_m": camera.elevation_m,
            "view_width_m": camera.view_width_m,
            "px_per_m_table": camera.px_per_m(0.0),
        },
        created_by=created_by,
        training={
            "experiments": len(rows),
            "seed": seed,
            "fps": fps,
            "naming": "each cluster named after the majority ground truth of its members "
            "(Hungarian assignment), standing in for a person naming them",
            "agreement_with_truth": agreement,
        },
    )
    return model, rows, truth
