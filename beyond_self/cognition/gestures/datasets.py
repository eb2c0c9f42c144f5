"""Labelled gestures from the places the CLI accepts: synthetic, or recordings on disk.

`synthetic` (the seeded generator, cut by the default segmenter), a folder of the article's hand
recordings whose sub-folders are named after their action (`push` left out unless `push_as` says
what to count it as: the article used its push model as touch), one such recording, or a
skeleton stream from an MCAP recording (`skeleton_gestures`, cut at given bounds or by the
segmenter). Every gesture keeps the recording it came from, so cross-validation can leave whole
recordings out, and its frames in both feature spaces (`in_space`).
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from beyond_self.cognition.gestures.evaluation import LabelledGesture
from beyond_self.cognition.gestures.features import (
    LOG_SCALE,
    MOTION,
    features_from_joints,
    gesture_features,
)
from beyond_self.cognition.gestures.logs import hand_log_stream
from beyond_self.cognition.gestures.segmentation import SegmenterConfig, segment_gestures
from beyond_self.cognition.gestures.synthetic import (
    SynthesisConfig,
    gesture_seed,
    synthesize_gesture,
)
from beyond_self.cognition.variables import ACTIONS
from beyond_self.core.errors import InputError

SYNTHETIC = "synthetic"
_NAME = re.compile(r"(?:^|[_-])(grasp|tap|touch|push)(?![a-z])")

# The article's own gesture ranges (1-based, inclusive) in its recordings, from its MATLAB code
# (gsaponaro/tcds-gestures: misc/glu_gestures.m, the visual bounds shrunk by 10 frames, and
# evolution_of_action_posterior_{sphere,box}.m). The article gives none for the other logs.
ARTICLE_RANGES: dict[str, tuple[tuple[int, int], ...]] = {
    "tap1_hand": ((216, 351), (401, 511), (557, 664)),
    "tap_notable_seated_1": ((121, 214),),
    "norobotview_tap_notable_seated_2": ((230, 375),),
}

FloatArray = NDArray[np.float64]


def _cut(
    action: str,
    positions: FloatArray,
    start: int,
    stop: int,
    source: str,
    recording: str,
) -> LabelledGesture:
    """One gesture: frames [start, stop) of a stream of positions (body units)."""
    return LabelledGesture(
        action=action,
        features=gesture_features(MOTION, positions, start, stop),
        source=source,
        positions=positions[start:stop].copy(),
        recording=recording,
    )


def synthetic_gestures(
    n_per_action: int, seed: int, config: SynthesisConfig | None = None
) -> list[LabelledGesture]:
    """n_per_action synthetic gestures of each action (seeds as `synthesize_dataset`)."""
    if n_per_action < 1:
        raise InputError(f"gestures per action {n_per_action}; valid: at least 1")
    out = []
    for a_i, action in enumerate(ACTIONS):
        for i in range(n_per_action):
            stream = synthesize_gesture(action, gesture_seed(seed, a_i, i), config)
            start, stop = stream.gesture_span()
            name = f"synthetic seed {seed} {action} #{i}"
            out.append(_cut(action, stream.features(), start, stop, name, name))
    return out


def _label(word: str, push_as: str | None) -> str | None:
    if word != "push":
        return word
    if push_as is None:
        return None
    if push_as not in ACTIONS:
        raise InputError(f"push_as {push_as!r} is not an action; valid: {', '.join(ACTIONS)}")
    return push_as


def recording_label(folder: Path, push_as: str | None) -> str | None:
    """The action of a recording folder from its name (<action>...); None when not used."""
    return action_from_name(folder.name, push_as)


def action_from_name(name: str, push_as: str | None = None) -> str | None:
    """The action a recording's name holds (tap.mcap, grasp_3.mcap, touch2, tap1_hand,
    norobotview_tap_notable_seated_2): the first action word in it, standing alone or before a
    digit."""
    m = _NAME.search(name)
    return None if m is None else _label(m.group(1), push_as)


def log_positions(folder: Path, scale: float = LOG_SCALE) -> FloatArray:
    """A hand log's positions in body units, checked as the pipeline checks them."""
    return hand_log_stream(folder, scale)[1]


def recording_gestures(
    folder: Path,
    action: str,
    scale: float = LOG_SCALE,
    segmenter: SegmenterConfig | None = None,
) -> list[LabelledGesture]:
    """The executions in one hand recording, segmented, as labelled gestures."""
    x = log_positions(folder, scale)
    return [
        _cut(
            action,
            x,
            seg.start,
            seg.stop,
            f"{folder.name} frames {seg.first}-{seg.last}",
            folder.name,
        )
        for seg in segment_gestures(x, segmenter)
    ]


def article_gestures(
    folder: Path, push_as: str | None = None, scale: float = LOG_SCALE
) -> list[LabelledGesture]:
    """The gestures of `ARTICLE_RANGES` in a folder of the article's recordings."""
    out = []
    for name, ranges in ARTICLE_RANGES.items():
        rec = folder / name
        action = recording_label(rec, push_as)
        if action is None or not (rec / "data.log").is_file():
            continue
        x = log_positions(rec, scale)
        for first, last in ranges:
            out.append(_cut(action, x, first - 1, last, f"{name} frames {first}-{last}", name))
    if not out:
        raise InputError(
            f"{folder} holds none of the article's ranged recordings ({', '.join(ARTICLE_RANGES)})"
        )
    return out


def skeleton_gestures(
    joints: Mapping[str, ArrayLike],
    actions: Sequence[str],
    *,
    bounds: Sequence[tuple[int, int]] | None = None,
    source: str = "skeleton",
    segmenter: SegmenterConfig | None = None,
) -> list[LabelledGesture]:
    """Labelled gestures of a skeleton stream: one action per gesture, or one for all of them.

    `bounds`: [start, stop) frame pairs (0-based); by default the segmenter finds them.
    """
    x = features_from_joints(joints)
    if bounds is None:
        found = [(s.start, s.stop) for s in segment_gestures(x, segmenter)]
    else:
        found = [(int(a), int(b)) for a, b in bounds]
        for a, b in found:
            if not 0 <= a < b <= len(x):
                raise InputError(f"{source}: gesture frames {a}:{b} outside 0:{len(x)}")
    labels = list(actions)
    if len(labels) == 1:
        labels = labels * len(found)
    if len(labels) != len(found):
        raise InputError(
            f"{source}: {len(found)} gestures but {len(labels)} action labels; give one label "
            "per gesture, or their frame bounds"
        )
    for label in labels:
        if label not in ACTIONS:
            raise InputError(f"{source}: unknown action {label!r}; valid: {', '.join(ACTIONS)}")
    return [
        _cut(a, x, b0, b1, f"{source} frames {b0 + 1}-{b1}", source)
        for a, (b0, b1) in zip(labels, found, strict=True)
    ]


def load_gestures(
    spec: str | Path,
    *,
    n_per_action: int = 30,
    seed: int = 0,
    push_as: str | None = None,
    scale: float = LOG_SCALE,
    segmenter: SegmenterConfig | None = None,
) -> list[LabelledGesture]:
    """Labelled gestures from `synthetic`, a recordings folder, or one recording (see above)."""
    if str(spec) == SYNTHETIC:
        return synthetic_gestures(n_per_action, seed)
    path = Path(spec)
    if path.suffix.lower() == ".mcap":
        raise InputError(
            f"{path}: MCAP recordings are read by `beyond gesture` (runtime layer); here give "
            "'synthetic' or a folder of hand recordings (grasp1_hand/ ... with data.log)"
        )
    if not path.exists():
        raise InputError(
            f"{path} does not exist; valid: 'synthetic' or a folder of hand recordings"
        )
    if path.is_file():
        path = path.parent
    folders = (
        [path] if (path / "data.log").is_file() else sorted(p for p in path.iterdir() if p.is_dir())
    )
    out: list[LabelledGesture] = []
    used = 0
    for folder in folders:
        label = recording_label(folder, push_as)
        if label is None or not (folder / "data.log").is_file():
            continue
        used += 1
        out.extend(recording_gestures(folder, label, scale, segmenter))
    if used == 0:
        raise InputError(
            f"{path} holds no hand recordings named <action>... (grasp1_hand, tap1_hand, "
            "touch1_hand) with a data.log"
        )
    if not out:
        raise InputError(f"no gestures were found in the recordings under {path}")
    return out
