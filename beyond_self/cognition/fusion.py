"""Fusing gesture evidence with the Affordance–Words network: P_comb.

The robot never observes the person's action; a gesture recogniser gives P_HMM(A | G). The
article combines them in two cases: with A among the inferred variables, P_comb ∝ P_BN(X_inf |
X_obs) · P_HMM(A | G); with A latent, P_comb = Σ_A P_HMM(A | G) · P_BN(X_inf, A | X_obs). Both
equal entering P_HMM(A | G) as soft (virtual) evidence on A. The formulas are implemented
literally (`method="formula"`, the definition) and the soft-evidence route (`method="soft"`, one
compiled query) is what services run; a property test holds them equal to 1e-12.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Mapping, Sequence
from typing import Literal

import numpy as np

from beyond_self.cognition.bn.inference import Posterior
from beyond_self.cognition.bn.model import BayesNet
from beyond_self.core.errors import InputError, unknown

ACTION = "Action"
Method = Literal["soft", "formula"]


def action_vector(model: BayesNet, p_hmm: Mapping[str, float] | Sequence[float]) -> np.ndarray:
    """P_HMM(A | G) as a vector in the network's Action value order.

    A mapping is matched by action name (gesture models and network may list actions in different
    orders); a plain sequence must already be in the network's order.
    """
    return np.array(action_probabilities(model, p_hmm))


def action_probabilities(
    model: BayesNet, p_hmm: Mapping[str, float] | Sequence[float]
) -> list[float]:
    """`action_vector` as plain floats: a reasoner fuses every frame of every gesture, and on
    three actions numpy's per-call cost is most of the work."""
    actions = model.values[ACTION]
    if isinstance(p_hmm, Mapping):
        extra = [a for a in p_hmm if a not in actions]
        if extra:
            raise unknown("action in the gesture evidence", extra[0], actions)
        missing = [a for a in actions if a not in p_hmm]
        if missing:
            raise InputError(
                f"gesture evidence lacks action(s) {', '.join(missing)}; "
                f"give a probability for each of {', '.join(actions)}"
            )
        probabilities = [float(p_hmm[a]) for a in actions]
    else:
        probabilities = [float(p) for p in p_hmm]
        if len(probabilities) != len(actions):
            raise InputError(
                f"gesture evidence needs {len(actions)} probabilities ({', '.join(actions)}); "
                f"got {len(probabilities)}"
            )
    if not all(math.isfinite(p) and p >= 0 for p in probabilities) or not any(probabilities):
        raise InputError(
            f"gesture evidence must be finite, non-negative and not all zero; got {probabilities}"
        )
    total = sum(probabilities)
    return [p / total for p in probabilities]


def _check_observed(model: BayesNet, observed: Mapping[str, str]) -> None:
    if ACTION in observed:
        raise InputError(
            "the action is never observed directly in fusion: it comes from the gesture "
            f"evidence; remove {ACTION}={observed[ACTION]} from the evidence"
        )
    if ACTION not in model.variables:
        raise InputError(f"the network has no {ACTION} node; fusion needs one")


def fuse(
    model: BayesNet,
    query: str | Sequence[str],
    observed: Mapping[str, str],
    p_hmm: Mapping[str, float] | Sequence[float],
    *,
    method: Method = "soft",
) -> Posterior:
    """P_comb(query | observed, G) for any query variables (a joint table when several)."""
    _check_observed(model, observed)
    names = [query] if isinstance(query, str) else list(query)
    vec = action_vector(model, p_hmm)
    if method == "soft":
        return model.query(names, observed, {ACTION: vec.tolist()})
    if method != "formula":
        raise unknown("fusion method", method, ("soft", "formula"))
    if ACTION in names:  # case 1: multiply along the Action axis and renormalise
        bn = model.query(names, observed)
        shape = [1] * len(names)
        shape[names.index(ACTION)] = vec.size
        table = bn.table * vec.reshape(shape)
    else:  # case 2: joint with the action, weight by P_HMM, sum the action out
        bn = model.query([*names, ACTION], observed)
        table = np.tensordot(bn.table, vec, axes=([len(names)], [0]))
    total = float(table.sum())
    if total <= 0:
        raise InputError(
            "the gesture evidence contradicts the observed variables: every action it allows "
            "has zero probability under the network given the evidence"
        )
    values = tuple(model.values[n] for n in names)
    return Posterior(tuple(names), values, table / total)


def fuse_marginals(
    model: BayesNet,
    queries: Sequence[str],
    observed: Mapping[str, str],
    p_hmm: Mapping[str, float] | Sequence[float],
) -> dict[str, dict[str, float]]:
    """P_comb(X | observed, G) for each X of `queries` (Action among them or not), each its own
    marginal: what `fuse` gives one variable at a time, equal to it within rounding.

    Why: a gesture's evidence changes every frame while what is observed (the object's
    features) stays for the whole gesture. P_BN(A, X | X_obs) is kept per observed set
    (`CompiledNetwork.pair_tables`), so a frame costs one product with P_HMM(A | G) per variable
    (case 2 of the formula, and case 1 for the action itself) instead of a sum over the
    network's whole joint per variable."""
    _check_observed(model, observed)
    vec = action_probabilities(model, p_hmm)
    compiled = model.compiled
    actions, *tables = compiled.pair_columns(ACTION, [ACTION, *queries], observed)
    # P_BN(A, A | observed) is diagonal: its columns' sums are P_BN(A | observed)
    total = sum(map(operator.mul, vec, map(sum, actions)))  # G-weighted, unscaled
    if not total > 0:  # the refusal's message, built only when it is needed
        compiled.check_total(total, observed, {ACTION: vec})
    out: dict[str, dict[str, float]] = {}
    for name, columns in zip(queries, tables, strict=True):
        weighted = [sum(map(operator.mul, vec, column)) for column in columns]
        scale = sum(weighted)
        out[name] = dict(zip(model.values[name], [w / scale for w in weighted], strict=True))
    return out


def fuse_words(
    model: BayesNet,
    observed: Mapping[str, str],
    p_hmm: Mapping[str, float] | Sequence[float],
    *,
    method: Method = "soft",
) -> dict[str, float]:
    """P_comb(word present | observed, G) for every word node, keyed by the word (case 2)."""
    _check_observed(model, observed)
    vec = action_vector(model, p_hmm)
    if method == "soft":
        return model.word_probabilities(observed, {ACTION: vec.tolist()})
    if method != "formula":
        raise unknown("fusion method", method, ("soft", "formula"))
    # Σ_A P_HMM(A) P_BN(w, A | obs) / Σ_A P_HMM(A) P_BN(A | obs), with P_BN(w, A | obs) =
    # P_BN(w | A, obs) P_BN(A | obs); actions impossible given obs contribute nothing.
    p_action = model.query(ACTION, observed).table
    weights = vec * p_action
    total = float(weights.sum())
    if total <= 0:
        raise InputError(
            "the gesture evidence contradicts the observed variables: every action it allows "
            "has zero probability under the network given the evidence"
        )
    out: dict[str, float] = {}
    for action, w in zip(model.values[ACTION], weights, strict=True):
        if w == 0:
            continue
        words = model.word_probabilities({**observed, ACTION: action})
        for word, p in words.items():
            out[word] = out.get(word, 0.0) + w * p
    return {word: p / total for word, p in out.items()}
