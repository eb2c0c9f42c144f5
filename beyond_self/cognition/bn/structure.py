"""K2 structure search with the BIC score, as the reference (BNT's learn_struct_K2) runs it.

Nodes in the definition's order; each greedily takes the candidate parent that strictly raises
its score, until none does or `max_parents`; ties go to the earliest candidate (MATLAB's `max`).
The roots (Action, Color, Shape, Size) take none, an affordance node any affordance node before
it, a word node any affordance node. BIC with maximum-likelihood parameters is pgmpy's
`structure_score.BIC` (the reference in tests and the benchmark); `bnt_prior=True` plugs in the
BDeu parameters BNT would learn. Both give the article's graph. One `np.bincount` per family is
what makes the search take milliseconds.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from typing import Literal, Protocol

import numpy as np

from beyond_self.cognition.bn.bag import Dataset
from beyond_self.core.errors import InputError, unknown

DEFAULT_ROOTS: tuple[str, ...] = ("Action", "Color", "Shape", "Size")
DEFAULT_MAX_PARENTS = 10


class Scorer(Protocol):
    def local_score(self, child: int, parents: tuple[int, ...]) -> float: ...


def family_counts(
    data: np.ndarray, cards: Sequence[int], child: int, parents: Sequence[int]
) -> np.ndarray:
    """Counts N[j, k]: rows with parent configuration j (first parent slowest) and child value k."""
    config = np.zeros(data.shape[0], dtype=np.int64)
    q = 1
    for p in parents:
        config = config * cards[p] + data[:, p]
        q *= cards[p]
    r = cards[child]
    return np.bincount(config * r + data[:, child], minlength=q * r).reshape(q, r)


def log_likelihood(counts: np.ndarray, cpt: np.ndarray) -> float:
    """sum N_jk log theta_jk; a zero-probability cell that was observed gives -inf."""
    seen = counts > 0
    with np.errstate(divide="ignore"):
        return float(np.sum(counts[seen] * np.log(cpt[seen])))


def ml_log_likelihood(counts: np.ndarray) -> float:
    """Log-likelihood at the maximum-likelihood parameters, from the counts alone."""
    counts = counts.astype(float)
    totals = counts.sum(axis=1, keepdims=True)
    nz = counts > 0
    return float(np.sum(counts[nz] * np.log((counts / np.where(totals > 0, totals, 1.0))[nz])))


class CountingScorer:
    """Our BIC: vectorised counting on the integer-coded table."""

    def __init__(self, dataset: Dataset, bnt_prior: bool = False, ess: float = 1.0) -> None:
        self.data = dataset.data
        self.cards = dataset.definition.cards
        self.rows = dataset.rows
        self.log_n = math.log(max(dataset.rows, 1))
        self.prior_nodes = (
            {i for i, v in enumerate(dataset.definition.variables) if not v.is_word}
            if bnt_prior
            else set()
        )
        self.ess = ess

    def local_score(self, child: int, parents: tuple[int, ...]) -> float:
        counts = family_counts(self.data, self.cards, child, parents)
        q, r = counts.shape
        if child in self.prior_nodes:
            smoothed = counts + self.ess / (q * r)
            ll = log_likelihood(counts, smoothed / smoothed.sum(axis=1, keepdims=True))
        else:
            ll = ml_log_likelihood(counts)
        return float(ll - 0.5 * q * (r - 1) * self.log_n)


class PgmpyScorer:
    """pgmpy's BIC on a pandas frame of value names: the reference our scorer must equal."""

    def __init__(self, dataset: Dataset) -> None:
        import pandas as pd

        with warnings.catch_warnings():  # pgmpy 1.1 warns about its own deprecated module
            warnings.simplefilter("ignore", FutureWarning)
            from pgmpy.structure_score import BIC

        definition = dataset.definition
        frame = pd.DataFrame(
            {
                v.name: np.asarray(v.values, dtype=object)[dataset.data[:, i]]
                for i, v in enumerate(definition.variables)
            }
        )
        self.names = definition.names
        self.bic = BIC(frame, state_names={v.name: list(v.values) for v in definition.variables})

    def local_score(self, child: int, parents: tuple[int, ...]) -> float:
        return float(self.bic.local_score(self.names[child], tuple(self.names[p] for p in parents)))


def candidate_parents(dataset: Dataset, roots: Sequence[str]) -> dict[int, tuple[int, ...]]:
    """Which nodes each node may choose parents from (the K2 order restricted as the article
    does, docs/science/network.md)."""
    definition = dataset.definition
    root_set = set(roots)
    for name in roots:
        if name not in definition or definition[name].is_word:
            valid = [v.name for v in definition.affordance]
            raise unknown("root node (must be an affordance node)", name, valid)
    affordance = [i for i, v in enumerate(definition.variables) if not v.is_word]
    out: dict[int, tuple[int, ...]] = {}
    for i, var in enumerate(definition.variables):
        if var.name in root_set:
            out[i] = ()
        elif var.is_word:
            out[i] = tuple(affordance)
        else:
            out[i] = tuple(j for j in affordance if j < i)
    return out


def k2_search(
    dataset: Dataset,
    *,
    roots: Sequence[str] = DEFAULT_ROOTS,
    max_parents: int = DEFAULT_MAX_PARENTS,
    scorer: Literal["counts", "pgmpy"] | Scorer = "counts",
    bnt_prior: bool = False,
    on_node: Callable[[str, tuple[str, ...]], None] | None = None,
) -> dict[str, tuple[str, ...]]:
    """Parents of every node (in node order), found greedily as described above."""
    if max_parents < 0:
        raise InputError(f"max_parents must be >= 0; got {max_parents}")
    if dataset.rows == 0:
        raise InputError(f"{dataset.source}: no rows to learn from")
    score: Scorer
    if scorer == "counts":
        score = CountingScorer(dataset, bnt_prior=bnt_prior)
    elif scorer == "pgmpy":
        if bnt_prior:
            raise InputError("bnt_prior needs scorer='counts' (pgmpy's BIC is maximum likelihood)")
        score = PgmpyScorer(dataset)
    elif isinstance(scorer, str):
        raise unknown("scorer", scorer, ["counts", "pgmpy"])
    else:
        score = scorer
    names = dataset.definition.names
    candidates = candidate_parents(dataset, roots)
    parents: dict[str, tuple[str, ...]] = {}
    for child, name in enumerate(names):
        chosen: list[int] = []
        best = score.local_score(child, ())
        while len(chosen) < max_parents:
            pool = [p for p in candidates[child] if p not in chosen]
            if not pool:
                break
            scores = [score.local_score(child, tuple(sorted((*chosen, p)))) for p in pool]
            k = int(np.argmax(scores))
            if not scores[k] > best:
                break
            best = scores[k]
            chosen.append(pool[k])
        parents[name] = tuple(names[p] for p in sorted(chosen))
        if on_node is not None:
            on_node(name, parents[name])
    return parents
