"""Experiment 3, effect anticipation: a recorded human tap recognised frame by frame, and the
effects anticipated from it as the gesture unfolds (docs/science/reproduce.md)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from beyond_self.cognition.bn.model import BayesNet
from beyond_self.cognition.descriptions import nbest_exact
from beyond_self.cognition.fusion import fuse, fuse_words
from beyond_self.cognition.gestures.log_evidence import recognize_log
from beyond_self.cognition.reproduction.inputs import Inputs

EXP3_FRAMES = (121, 214)

EXP3_EVERY = 5


def exp3(inputs: Inputs) -> dict[str, Any]:
    """Effect anticipation on a recorded human tap, fused every EXP3_EVERY frames."""
    model = inputs.model
    first, last = EXP3_FRAMES
    result, _ = recognize_log(inputs.gestures, inputs.recording, f"{first}:{last}")
    actions = list(result.actions)
    posterior = result.posterior
    argmax = posterior.argmax(axis=1)
    tap = actions.index("tap")
    stays = len(argmax)
    while stays > 0 and argmax[stays - 1] == tap:
        stays -= 1
    steps = [*range(EXP3_EVERY, len(result) + 1, EXP3_EVERY)]
    if steps[-1] != len(result):
        steps.append(len(result))
    anticipation = anticipate(model, actions, posterior, steps)
    final = by_action(actions, posterior[-1])
    words = fuse_words(model, {"Shape": "circle", "Size": "small"}, final)
    return {
        "frames": [first, last],
        "actions": actions,
        "loglik": result.loglik.tolist(),
        "normalized": result.normalized.tolist(),
        "posterior": posterior.tolist(),
        "final_loglik": result.loglik[-1].tolist(),
        "final_posterior": posterior[-1].tolist(),
        # 1-based frame of the recording from which tap stays the most probable action
        "tap_stays_argmax_from_frame": first + stays if stays < len(argmax) else None,
        "tap_stays_argmax_from_gesture_frame": stays + 1 if stays < len(argmax) else None,
        "steps": steps,
        "anticipation": anticipation,
        "description": [(s.sentence, s.score) for s in nbest_exact(words, 3)],
    }


def anticipate(
    model: BayesNet, actions: Sequence[str], posterior: np.ndarray, steps: Sequence[int]
) -> dict[str, list[list[float]]]:
    """P_comb(ObjVel | Shape, Size=small, G_1^t) at the given gesture frames t, by shape."""
    out: dict[str, list[list[float]]] = {}
    for shape in ("circle", "box"):
        observed = {"Shape": shape, "Size": "small"}
        out[shape] = [
            fuse(model, "ObjVel", observed, by_action(actions, posterior[t - 1])).table.tolist()
            for t in steps
        ]
    return out


def by_action(actions: Sequence[str], probs: Sequence[float]) -> dict[str, float]:
    return {a: float(p) for a, p in zip(actions, probs, strict=True)}
