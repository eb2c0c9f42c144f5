"""Conditional probability tables from counts, with the reference's priors and its unseen rule.

Affordance nodes: BDeu Dirichlet prior with equivalent sample size `ess` (1 in the reference): a
pseudo-count ess/(q·r) in every cell, q parent configurations, r values. A configuration never seen
in training thus gets the uniform distribution.

Word nodes: maximum likelihood. For a parent configuration never seen in training the counts are
all zero and maximum likelihood is undefined. The rule is an explicit choice (`unseen`), and each
is a different model (README.md beside this file compares them on the article's tables):

- "absent" (default): P(absent) = 1. The configuration stays in the joint and the word is never
  said there. A proper Bayesian network (what pgmpy requires); the article's "and"/"but" lists.
- "zero": the column stays all zero, as the reference toolbox (BNT) leaves it. Summing the word
  out then gives 0, not 1, so the configuration leaves the *joint*: every query renormalises over
  the configurations every word has seen. This is the model behind the article's Table II.
- "uniform": 1/r for every value.
- "dirichlet": give word nodes a BDeu prior of equivalent sample size `word_ess` as well, which
  changes every word column slightly, not only the unseen ones.
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
