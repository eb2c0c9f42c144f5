"""Gesture evidence from a recorded hand log: P_HMM(A | G) after the last frame of a span.

One function, so `beyond gesture stream`, the `--gesture-log` option of the network commands and the
article's experiments all cut, scale and recognise a log the same way: the span is the gesture,
the frames before it are context (the "motion" features start from the span's first frame and
smooth over the frames before it, as the streaming recogniser would have).
"""

from __future__ import annotations

from pathlib import Path

from beyond_self.cognition.gestures.features import LOG_SCALE, extract_features, gesture_features
from beyond_self.cognition.gestures.hmm import GestureModels
from beyond_self.cognition.gestures.logs import parse_frames, read_hand_log
from beyond_self.cognition.gestures.streaming import SequenceResult, recognize_sequence


def recognize_log(
    models: GestureModels,
    log_path: str | Path,
    frames: str | None = None,
    scale: float = LOG_SCALE,
) -> tuple[SequenceResult, int]:
    """Recognise frames `frames` ("A:B", 1-based inclusive) of a hand log; returns the per-frame
    result and the 1-based number of the first frame used."""
    log = read_hand_log(log_path)
    span = parse_frames(frames, len(log))
    x = extract_features(log.xyz, scale=scale)
    features = gesture_features(models.features, x, span.start, span.stop)
    return recognize_sequence(models, features), span.start + 1
