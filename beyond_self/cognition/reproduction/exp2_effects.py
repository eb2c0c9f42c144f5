"""Experiment 2, effect prediction: P_comb(ObjVel | Shape, G) for mixes of touch and tap
evidence, and the network alone (docs/science/reproduce.md)."""

from __future__ import annotations

from collections.abc import Sequence

from beyond_self.cognition.bn.model import BayesNet
from beyond_self.cognition.fusion import ACTION, fuse

EXP2_MIXES = ((1.0, 0.0), (0.75, 0.25), (0.5, 0.5), (0.25, 0.75), (0.0, 1.0))  # touch : tap


def mix_label(vector: Sequence[float]) -> str:
    """`[0, 0.25, 0.75]`: a P_HMM vector in grasp, tap, touch order, as the results keys it."""
    return "[" + ", ".join(f"{x:g}" for x in vector) + "]"


def exp2(model: BayesNet) -> dict[str, dict[str, list[float]]]:
    """P_comb(ObjVel | Shape, G) for touch/tap mixes of gesture evidence, and the network alone."""
    actions = model.values[ACTION]
    out: dict[str, dict[str, list[float]]] = {}
    for shape in ("circle", "box"):
        rows = {"none": model.query("ObjVel", {"Shape": shape}).table.tolist()}
        for touch, tap in EXP2_MIXES:
            vec = [{"touch": touch, "tap": tap}.get(a, 0.0) for a in actions]
            rows[mix_label(vec)] = fuse(model, "ObjVel", {"Shape": shape}, vec).table.tolist()
        out[shape] = rows
    return out
