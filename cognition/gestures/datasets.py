"""Labelled gestures from the places the CLI accepts: synthetic, or recordings on disk.

- `synthetic`: the seeded generator (`cognition.gestures.synthetic`), N gestures per action.
- a folder of the article's hand recordings (like `human_data/`): every sub-folder named
  `<action><n>...` (grasp1_hand, tap1_hand, touch1_hand, push1_hand) holds repeated executions
  of one action; each is cut into repetitions by the segmenter. `push` recordings are left out
  unless `push_as` names the action to count them as (the article used its push model as touch;
  with real touch recordings at hand, mixing a different movement into touch blurs that class).
- one recording folder (or its data.log) named the same way.
- an MCAP recording: not read yet (the recording layer lives in `runtime/`).
"""

from __future__ import annotations

import re
from pathlib import Path

from cognition.errors import InputError
from cognition.gestures.evaluation import LabelledGesture
from cognition.gestures.features import LOG_SCALE, extract_features
from cognition.gestures.logs import read_hand_log
from cognition.gestures.segmentation import SegmenterConfig, segment_gestures
from cognition.gestures.synthetic import SynthesisConfig, synthesize_dataset
from cognition.variables import ACTIONS

SYNTHETIC = "synthetic"
_NAME = re.compile(r"^(grasp|tap|touch|push)\d")


def synthetic_gestures(
    n_per_action: int, seed: int, config: SynthesisConfig | None = None
) -> list[LabelledGesture]:
    data = synthesize_dataset(n_per_action, seed, config)
    return [
        LabelledGesture(action=a, features=x, source=f"synthetic seed {seed} {a} #{i}")
        for a, xs in data.items()
        for i, x in enumerate(xs)
    ]


def recording_label(folder: Path, push_as: str | None) -> str | None:
    """The action of a recording folder from its name; None when it is not used."""
    m = _NAME.match(folder.name)
    if m is None:
        return None
    label = m.group(1)
    if label == "push":
        if push_as is None:
            return None
        if push_as not in ACTIONS:
            raise InputError(f"push_as {push_as!r} is not an action; valid: {', '.join(ACTIONS)}")
        return push_as
    return label


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
            f"{path}: MCAP input is not supported yet; valid: 'synthetic' or a folder of hand "
            "recordings (grasp1_hand/ ... with data.log)"
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
