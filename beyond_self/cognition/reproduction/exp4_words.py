"""Experiment 4, word prediction: how much each word's probability moves when the action is
known to be a tap (docs/science/reproduce.md)."""

from __future__ import annotations

from beyond_self.cognition.bn.model import BayesNet
from beyond_self.cognition.fusion import ACTION

EXP4_OBSERVED = {"Color": "yellow", "Size": "big", "Shape": "circle", "ObjVel": "fast"}


def exp4(model: BayesNet) -> dict[str, float]:
    """ΔP(w) = P(w | X_obs, Action=tap) − P(w | X_obs)."""
    with_tap = model.word_probabilities({**EXP4_OBSERVED, ACTION: "tap"})
    without = model.word_probabilities(EXP4_OBSERVED)
    return {w: with_tap[w] - without[w] for w in without}
