"""Experiment 1, conflicting evidence: the network favours touch; from how much gesture
evidence on tap does tap win (docs/science/reproduce.md)?"""

from __future__ import annotations

from typing import Any

import numpy as np

from beyond_self.cognition.bn.model import BayesNet
from beyond_self.cognition.fusion import ACTION, fuse

EXP1_OBSERVED = {"Size": "small", "Shape": "circle", "ObjVel": "slow"}


def _tap_vector(model: BayesNet, p_tap: float, other: str | None = None) -> list[float]:
    """P_HMM with p_tap on tap and the rest shared equally (or all on `other`)."""
    actions = model.values[ACTION]
    rest = [a for a in actions if a != "tap"]
    out = {"tap": p_tap}
    for a in rest:
        if other is None:
            out[a] = (1.0 - p_tap) / len(rest)
        else:
            out[a] = (1.0 - p_tap) if a == other else 0.0
    return [out[a] for a in actions]


def exp1(model: BayesNet) -> dict[str, Any]:
    """Conflicting evidence: the network favours touch; where does tap gesture evidence win?

    With P_HMM = (x on tap, (1-x)/2 on each other action), P_comb(a) ∝ P_BN(a) P_HMM(a), so tap is
    the most probable exactly when x·P_BN(tap) > (1-x)/2·P_BN(o) for every other action o:
    x > P_BN(o) / (2 P_BN(tap) + P_BN(o)). The threshold is the largest of those.
    """
    actions = model.values[ACTION]
    p_bn = model.query(ACTION, EXP1_OBSERVED).table
    tap = actions.index("tap")
    bounds = [p_bn[i] / (2 * p_bn[tap] + p_bn[i]) for i in range(len(actions)) if i != tap]
    threshold = float(max(bounds))
    sweep = np.linspace(1 / 3, 1.0, 201)
    curves = np.array(
        [fuse(model, ACTION, EXP1_OBSERVED, _tap_vector(model, x)).table for x in sweep]
    )
    return {
        "observed": EXP1_OBSERVED,
        "actions": list(actions),
        "pbn_action": p_bn.tolist(),
        "tap_threshold": threshold,
        "sweep": sweep.tolist(),
        "pcomb": curves.tolist(),
    }
