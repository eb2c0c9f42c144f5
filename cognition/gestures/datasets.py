"""Labelled gestures from the places the CLI accepts: synthetic, or recordings on disk.

- `synthetic`: the seeded generator (`cognition.gestures.synthetic`), N gestures per action.
- a folder of the article's hand recordings (like `human_data/`): every sub-folder named
  `<action><n>...` (grasp1_hand, tap1_hand, touch1_hand, push1_hand) holds repeated executions
  of one action; each is cut into repetitions by the segmenter. `push` recordings are left out
  unless `push_as` names the action to count them as (the article used its push model as touch;
  with real touch recordings at hand, mixing a different movement into touch blurs that class).
- one recording folder (or its data.log) named the same way.
- a skeleton stream (joint name -> (T, 3) positions in metres, as in an MCAP recording, which
  `beyond gesture` reads through `runtime.recording`): `skeleton_gestures` labels its gestures,
  cut at given frame bounds or by the segmenter.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from pathlib import Path

from numpy.typing import ArrayLike

from beyond_self.cognition.gestures.evaluation import LabelledGesture
from beyond_self.cognition.gestures.features import (
    LOG_SCALE,
    extract_features,
    features_from_joints,
)
from beyond_self.cognition.gestures.logs import read_hand_log
from beyond_self.cognition.gestures.segmentation import SegmenterConfig, segment_gestures
from beyond_self.cognition.gestures.synthetic import SynthesisConfig, synthesize_dataset
from beyond_self.cognition.variables import ACTIONS
from beyond_self.core.errors import InputError

SYNTHETIC = "synthetic"
_NAME = re.compile(r"^(grasp|tap|touch|push)\d")
_FILE_NAME = re.compile(r"^(grasp|tap|touch|push)(?![a-z])")


def synthetic_gestures(
    n_per_action: int, seed: int, config: SynthesisConfig | None = None
) -> list[LabelledGesture]:
    data = synthesize_dataset(n_per_action, seed, config)
    return [
        LabelledGesture(action=a, features=x, source=f"synthetic seed {seed} {a} #{i}")
        for a, xs in data.items()
        for i, x in enumerate(xs)
    ]


def _label(word: str, push_as: str | None) -> str | None:
    if word != "push":
        return word
    if push_as is None:
        return None
    if push_as not in ACTIONS:
        raise InputError(f"push_as {push_as!r} is not an action; valid: {', '.join(ACTIONS)}")
    return push_as


def recording_label(folder: Path, push_as: str | None) -> str | None:
    """The action of a recording folder from its name (<action><n>...); None when not used."""
    m = _NAME.match(folder.name)
    return None if m is None else _label(m.group(1), push_as)


def action_from_name(name: str, push_as: str | None = None) -> str | None:
    """The action a recording file's name starts with (tap.mcap, grasp_3.mcap, touch2.mcap)."""
    m = _FILE_NAME.match(name)
    return None if m is None else _label(m.group(1), push_as)


def recording_gestures(
    folder: Path,
    action: str,
    scale: float = LOG_SCALE,
    segmenter: SegmenterConfig | None = None,
) -> list[LabelledGesture]:
    """The repetitions in one hand recording, segmented, as labelled feature sequences."""
    log = read_hand_log(folder, min_frames=2)
    feats = extract_features(log.xyz, scale=scale)
    out = []
    for seg in segment_gestures(feats, segmenter):
        out.append(
            LabelledGesture(
                action=action,
                features=feats[seg.start : seg.stop],
                source=f"{folder.name} frames {seg.first}-{seg.last}",
            )
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
    feats = features_from_joints(joints)
    if bounds is None:
        found = [(s.start, s.stop) for s in segment_gestures(feats, segmenter)]
    else:
        found = [(int(a), int(b)) for a, b in bounds]
        for a, b in found:
            if not 0 <= a < b <= len(feats):
                raise InputError(f"{source}: gesture frames {a}:{b} outside 0:{len(feats)}")
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
        LabelledGesture(action=a, features=feats[b0:b1], source=f"{source} frames {b0 + 1}-{b1}")
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
            f"{path} holds no hand recordings named <action><n>... (grasp1_hand, tap1_hand, "
            "touch1_hand) with a data.log"
        )
    if not out:
        raise InputError(f"no gestures were found in the recordings under {path}")
    return out
