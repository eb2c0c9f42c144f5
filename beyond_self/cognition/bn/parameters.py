"""Conditional probability tables from counts, with the reference's priors and its unseen rule.

Affordance nodes: a BDeu Dirichlet prior of equivalent sample size `ess` (1 in the reference), so
a configuration never seen in training gets the uniform distribution. Word nodes: maximum
likelihood, undefined for a parent configuration never seen; what goes there is an explicit
choice (`unseen`: "absent", "zero", "uniform", "dirichlet"), and each is another model
(docs/science/network.md compares them; "zero" is the reference toolbox's, behind the article's
Table II).
"""

from __future__ import annotations

from typing import Literal, cast

import numpy as np

from beyond_self.core.errors import InputError, unknown

UnseenRule = Literal["absent", "zero", "uniform", "dirichlet"]
UNSEEN_RULES: tuple[str, ...] = ("absent", "zero", "uniform", "dirichlet")
ML_RULES = ("absent", "zero", "uniform")  # the rules that keep maximum likelihood on seen columns


def bdeu_cpt(counts: np.ndarray, ess: float) -> np.ndarray:
    """Posterior-mean CPT under a BDeu prior: (N_jk + ess/(q r)) / (N_j + ess/q). Rows = configs."""
    if ess <= 0:
        raise InputError(f"equivalent sample size must be > 0; got {ess}")
    q, r = counts.shape
    smoothed = counts + ess / (q * r)
    return np.asarray(smoothed / smoothed.sum(axis=1, keepdims=True), dtype=float)


def ml_cpt(counts: np.ndarray, unseen: str, absent_index: int = 0) -> np.ndarray:
    """Maximum-likelihood CPT; rows with no counts follow `unseen` ("absent", "zero", "uniform")."""
    q, r = counts.shape
    totals = counts.sum(axis=1, keepdims=True)
    cpt = np.divide(counts, totals, out=np.zeros((q, r)), where=totals > 0)
    empty = totals[:, 0] == 0
    if unseen == "absent":
        cpt[empty, absent_index] = 1.0
    elif unseen == "uniform":
        cpt[empty, :] = 1.0 / r
    elif unseen != "zero":
        raise unknown("rule for unseen parent configurations", unseen, ML_RULES)
    return cast(np.ndarray, cpt)


def word_cpt(counts: np.ndarray, unseen: str, word_ess: float = 1.0) -> np.ndarray:
    """A word node's CPT (value 0 is `-`, absent) under the chosen unseen rule."""
    if unseen == "dirichlet":
        return bdeu_cpt(counts, word_ess)
    if unseen not in UNSEEN_RULES:
        raise unknown("rule for unseen parent configurations", unseen, UNSEEN_RULES)
    return ml_cpt(counts, unseen, absent_index=0)
