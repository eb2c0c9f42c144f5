"""Exact inference on the Affordance–Words network, compiled to a few numpy array operations.

Only the affordance nodes (2,592 joint states in the article) have children, and every word is a
leaf of them: so their joint is one small array computed once, and a query multiplies it by one
likelihood vector per piece of evidence, normalises and sums out the rest; all words' P(present)
is one matrix–vector product. It agrees with pgmpy (`pgmpy_bridge`) to rounding and is hundreds of
times faster, which fusion needs at every gesture frame. An all-zero word row (unseen="zero")
removes its parent configuration from the joint, as in the reference toolbox. Soft evidence is a
likelihood vector in definition order, as pgmpy's virtual evidence; evidence the model gives
zero probability is an InputError.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from beyond_self.cognition.bn.definition import Variable
from beyond_self.core.errors import InputError, unknown

MAX_CORE_STATES = 5_000_000
# Work per query is capped, with the limit in the message (the reasoner and `beyond bn query`
# share it): 18 word variables made 262,144 rows and blocked the reasoner for 4.7 s, x4 per two
# more words. Rows: the product of the queried variables' cardinalities; 4,096 hold the joint of
# all eight affordance nodes (2,592). Work, for a query with word variables: rows x affordance
# states summed over (each row sums over them); 2**21 cells take about 0.05 s (nine words).
MAX_JOINT_ROWS = 4096
# evidence sets whose pair tables are kept (CompiledNetwork.pair_tables): one per gesture of a fleet
_PAIR_TABLES_KEPT = 256
Columns = tuple[tuple[float, ...], ...]  # a table's columns as plain floats (pair_columns)
MAX_QUERY_WORK = 2**21


@dataclass(frozen=True)
class Posterior:
    """P(variables | evidence): `table[i, j, ...]` for `values[0][i]`, `values[1][j]`, ..."""

    variables: tuple[str, ...]
    values: tuple[tuple[str, ...], ...]
    table: np.ndarray

    def rows(self) -> Iterator[tuple[dict[str, str], float]]:
        """Every assignment with its probability, first variable varying slowest."""
        for index in np.ndindex(*self.table.shape):
            assignment = {
                v: vals[i] for v, vals, i in zip(self.variables, self.values, index, strict=True)
            }
            yield assignment, float(self.table[index])

    def marginal(self, variable: str) -> dict[str, float]:
        if variable not in self.variables:
            raise unknown("variable of this posterior", variable, self.variables)
        axis = self.variables.index(variable)
        others = tuple(i for i in range(len(self.variables)) if i != axis)
        probs = self.table.sum(axis=others) if others else self.table
        return {value: float(p) for value, p in zip(self.values[axis], probs, strict=True)}

    def probability(self, assignment: Mapping[str, str]) -> float:
        if set(assignment) != set(self.variables):
            raise InputError(
                f"assignment must name exactly {', '.join(self.variables)}; "
                f"got {', '.join(assignment)}"
            )
        index = []
        for v, vals in zip(self.variables, self.values, strict=True):
            if assignment[v] not in vals:
                raise unknown(f"value of {v}", assignment[v], vals)
            index.append(vals.index(assignment[v]))
        return float(self.table[tuple(index)])

    def as_dict(self) -> dict[str, Any]:
        """One variable: {VAR: {value: p}}; several: {"variables": [...], "rows": [...]}."""
        if len(self.variables) == 1:
            return {self.variables[0]: self.marginal(self.variables[0])}
        return {
            "variables": list(self.variables),
            "rows": [{"assignment": a, "p": p} for a, p in self.rows()],
        }


def check_likelihood(variable: Variable, likelihood: Sequence[float]) -> np.ndarray:
    """A soft-evidence vector as float array, or an InputError saying what is wrong with it.

    Checked in plain Python: the vectors are a handful of numbers and numpy's per-call overhead
    would dominate the query time.
    """
    try:
        values = [float(x) for x in likelihood]
    except (TypeError, ValueError):
        raise InputError(
            f"soft evidence on {variable.name} must be numbers; got {likelihood!r}"
        ) from None
    if len(values) != variable.card:
        raise InputError(
            f"soft evidence on {variable.name} needs {variable.card} numbers, one per value "
            f"({', '.join(variable.values)}); got {len(values)}"
        )
    if not all(math.isfinite(x) and x >= 0 for x in values) or not any(x > 0 for x in values):
        raise InputError(
            f"soft evidence on {variable.name} must be finite, non-negative and not all zero; "
            f"got {', '.join(map(str, values))}"
        )
    # Only a likelihood's ratios matter. Scaled by a power of two (exact) to a largest value in
    # [0.5, 1): a vector of tiny numbers (2.2e-308 for "surely v") would otherwise sink its
    # products with the network's probabilities into subnormals and lose their precision; an
    # ordinary vector's posterior comes out bit for bit the same either way.
    shift = -math.frexp(max(values))[1]
    return np.array([math.ldexp(x, shift) for x in values])


class CompiledNetwork:
    """The network as arrays: the joint over the core (non-leaf) nodes and one table per leaf."""

    def __init__(
        self,
        variables: Sequence[Variable],
        parents: Mapping[str, Sequence[str]],
        cpts: Mapping[str, np.ndarray],
    ) -> None:
        self.variables = {v.name: v for v in variables}
        has_children = {p for ps in parents.values() for p in ps}
        core = [v for v in variables if not v.is_word]
        self.core_names = tuple(v.name for v in core)
        self.leaf_names = tuple(v.name for v in variables if v.is_word)
        for name in self.leaf_names:
            if name in has_children:
                raise InputError(f"word node {name!r} has children; word nodes must be leaves")
        self.shape = tuple(v.card for v in core)
        self.size = math.prod(self.shape)
        if self.size > MAX_CORE_STATES:
            raise InputError(
                f"the affordance nodes have {self.size} joint states; compiled inference "
                f"supports up to {MAX_CORE_STATES}"
            )
        self.axis = {name: i for i, name in enumerate(self.core_names)}
        ndim = len(self.shape)
        joint = np.ones(self.shape)
        for name in self.core_names:
            joint = joint * self._broadcast(name, parents[name], cpts[name])
        # A word row of all zeros (unseen="zero", the reference toolbox's unseen column) sums to
        # 0 over the word's values, not 1: summing the word out multiplies the joint by 0 there,
        # so that parent configuration leaves the joint and every query renormalises over what
        # remains. One indicator over the core states carries it for every word. An observed,
        # soft or queried word multiplies by its own row as well, which is 0 exactly where the
        # indicator is, so counting it twice changes nothing.
        support = np.ones(self.shape, dtype=bool)
        for name in self.leaf_names:
            support &= self._broadcast(name, parents[name], cpts[name], leaf=True).sum(-1) > 0
        self.removed_mass = float(joint[~support].sum())  # prior mass ruled out, 0 if none
        if not support.all():
            joint = joint * support
        self.joint = joint.reshape(-1)
        # Leaf tables over the flat core states: (size, card) each.
        self.leaf_tables: dict[str, np.ndarray] = {}
        for name in self.leaf_names:
            table = self._broadcast(name, parents[name], cpts[name], leaf=True)
            card = self.variables[name].card
            full = np.broadcast_to(table, (*self.shape, card)).reshape(self.size, card)
            self.leaf_tables[name] = np.ascontiguousarray(full)
        self.words = tuple(self.variables[n].word for n in self.leaf_names)
        # P(present | core state) for every word: one row per word.
        self.present = (
            np.stack([self.leaf_tables[n][:, 1] for n in self.leaf_names])
            if self.leaf_names
            else np.zeros((0, self.size))
        )
        self._ndim = ndim
        self.joint_nd = self.joint.reshape(self.shape)
        self.leaf_nd = {n: t.reshape(*self.shape, -1) for n, t in self.leaf_tables.items()}
        self.present_nd = self.present.reshape(len(self.words), *self.shape)
        self._pair_tables: OrderedDict[tuple[Any, ...], dict[str, tuple[np.ndarray, Columns]]] = (
            OrderedDict()
        )

    def _broadcast(
        self, name: str, parents: Sequence[str], cpt: np.ndarray, leaf: bool = False
    ) -> np.ndarray:
        """A CPT (parents..., value) laid out along the core axes (value last for a leaf)."""
        for p in parents:
            if p not in self.axis:
                raise InputError(f"node {name!r} has parent {p!r}, which is not an affordance node")
        family = list(parents) if leaf else [*parents, name]
        axes = [self.axis[n] for n in family]
        order = np.argsort(axes)
        table = np.transpose(cpt, (*order, *([len(family)] if leaf else [])))
        shape = [1] * len(self.shape)
        for a in axes:
            shape[a] = self.shape[a]
        if leaf:
            shape.append(cpt.shape[-1])
        return table.reshape(shape)

    # -- evidence -------------------------------------------------------------------------------

    def _weights(
        self,
        evidence: Mapping[str, str],
        soft: Mapping[str, Sequence[float]],
        query: Sequence[str] = (),
    ) -> tuple[np.ndarray, tuple[int, ...], tuple[int | slice, ...]]:
        """The core joint restricted to the hard evidence (a view: observed axes sliced away),
        times every other evidence factor; the core axes it keeps; the index that sliced it.
        Its sum is P(evidence) up to the soft vectors' scales. A queried word's soft evidence
        is left out: it weighs that word's values, which the caller multiplies in."""
        for name in evidence:
            if name not in self.variables:
                raise unknown("evidence variable", name, tuple(self.variables))
        for name in soft:
            if name not in self.variables:
                raise unknown("soft-evidence variable", name, tuple(self.variables))
            if name in evidence:
                raise InputError(f"{name}: given both hard and soft evidence; give one")
        for name in query:
            if name in evidence:
                raise InputError(
                    f"{name}: both observed and queried; remove it from the evidence or the query"
                )
        index: list[int | slice] = [slice(None)] * self._ndim
        leaf_hard: list[tuple[str, int]] = []
        for name, value in evidence.items():
            code = self.variables[name].index(value)
            if name in self.axis:
                index[self.axis[name]] = code
            else:
                leaf_hard.append((name, code))
        idx = tuple(index)
        free = tuple(i for i, ix in enumerate(index) if isinstance(ix, slice))
        phi = self.joint_nd[idx]
        for name, likelihood in soft.items():
            vec = check_likelihood(self.variables[name], likelihood)
            if name in self.axis:
                shape = [1] * len(free)
                shape[free.index(self.axis[name])] = vec.size
                phi = phi * vec.reshape(shape)
            elif name not in query:
                phi = phi * (self.leaf_nd[name][idx] @ vec)
        for name, code in leaf_hard:
            phi = phi * self.leaf_nd[name][(*idx, code)]
        return phi, free, idx

    def check_total(
        self, total: float, evidence: Mapping[str, str], soft: Mapping[str, Sequence[float]]
    ) -> None:
        if not total > 0:
            shown = [f"{k}={v}" for k, v in evidence.items()] + [f"soft {k}" for k in soft]
            why = (
                " (its all-zero word columns, unseen=zero, rule out parent configurations "
                "never seen in training)"
                if self.removed_mass > 0
                else ""
            )
            raise InputError(
                f"the evidence has zero probability under the model{why} ({', '.join(shown)}); "
                "drop or change some of it"
            )

    # -- queries --------------------------------------------------------------------------------

    def posterior(
        self,
        query: Sequence[str],
        evidence: Mapping[str, str] | None = None,
        soft: Mapping[str, Sequence[float]] | None = None,
    ) -> Posterior:
        query = list(query)
        if not query:
            raise InputError("nothing to query; name at least one variable")
        for name in query:
            if name not in self.variables:
                raise unknown("query variable", name, tuple(self.variables))
        if len(set(query)) != len(query):
            raise InputError(f"query names a variable twice: {', '.join(query)}")
        rows = math.prod(self.variables[n].card for n in query)
        if rows > MAX_JOINT_ROWS:
            raise InputError(
                f"a joint query over {len(query)} variables has {rows} rows, over the limit of "
                f"{MAX_JOINT_ROWS}; query fewer variables at once (each alone gives its marginal)"
            )
        evidence = evidence or {}
        soft = soft or {}
        phi, free, idx = self._weights(evidence, soft, query)
        core_q = [n for n in query if n in self.axis]
        leaf_q = [n for n in query if n not in self.axis]
        if not leaf_q:
            pos = [free.index(self.axis[n]) for n in core_q]
            drop = tuple(i for i in range(len(free)) if i not in pos)
            table = phi.sum(axis=drop) if drop else phi
            if len(pos) > 1:  # table's axes are in core order; put them in query order
                kept = sorted(pos)
                table = np.transpose(table, [kept.index(p) for p in pos])
        else:
            work = rows * phi.size
            if work > MAX_QUERY_WORK:
                raise InputError(
                    f"a joint query over {len(query)} variables with words needs {rows} rows x "
                    f"{phi.size} affordance states = {work} cells, over the limit of "
                    f"{MAX_QUERY_WORK}; query fewer words at once (or give more evidence)"
                )
            labels = {n: self.axis[n] for n in core_q}
            operands: list[Any] = [phi, list(free)]
            for k, name in enumerate(leaf_q):
                labels[name] = self._ndim + k
                leaf = self.leaf_nd[name][idx]
                if name in soft:  # its likelihood weighs each of its values
                    leaf = leaf * check_likelihood(self.variables[name], soft[name])
                operands += [leaf, [*free, self._ndim + k]]
            operands.append([labels[n] for n in query])
            table = np.einsum(*operands, optimize=len(leaf_q) > 1)
        total = float(table.sum())
        self.check_total(total, evidence, soft)
        table = table / total
        values = tuple(self.variables[n].values for n in query)
        return Posterior(tuple(query), values, table)

    def pair_tables(
        self, pivot: str, variables: Sequence[str], evidence: Mapping[str, str]
    ) -> list[np.ndarray]:
        """P(pivot, X | evidence) for each X of `variables`, as (pivot values, X values)
        tables (for X = pivot, P(pivot | evidence) on the diagonal), kept for the last few
        evidence sets.

        Why kept: fusion asks for the same evidence frame after frame (an object's features stay
        for a whole gesture) with new soft evidence on the pivot each time; with these tables a
        frame costs one product with the soft vector per variable instead of a sum over the
        whole joint."""
        return [table for table, _ in self._pairs(pivot, variables, evidence)]

    def pair_columns(
        self, pivot: str, variables: Sequence[str], evidence: Mapping[str, str]
    ) -> list[Columns]:
        """`pair_tables` as plain floats: per X of `variables`, a column per value of X over
        the pivot's values. For a caller that works on a handful of numbers per call (fusion,
        every frame of a gesture), where numpy's per-call cost is most of the work."""
        return [columns for _, columns in self._pairs(pivot, variables, evidence)]

    def _pairs(
        self, pivot: str, variables: Sequence[str], evidence: Mapping[str, str]
    ) -> list[tuple[np.ndarray, Columns]]:
        """Each X's pair table and its columns, kept for the last few evidence sets."""
        key = (pivot, tuple(sorted(evidence.items())))
        kept = self._pair_tables.get(key)
        if kept is None:
            kept = self._pair_tables[key] = {}
            if len(self._pair_tables) > _PAIR_TABLES_KEPT:
                self._pair_tables.popitem(last=False)
        else:
            self._pair_tables.move_to_end(key)
        for name in variables:
            if name not in kept:
                if name == pivot:
                    table = np.diag(self.posterior([pivot], evidence).table)
                else:
                    table = self.posterior([pivot, name], evidence).table
                kept[name] = (table, tuple(tuple(float(p) for p in c) for c in table.T))
        return [kept[name] for name in variables]

    def word_probabilities(
        self,
        evidence: Mapping[str, str] | None = None,
        soft: Mapping[str, Sequence[float]] | None = None,
    ) -> dict[str, float]:
        """P(word present | evidence) for every word node (observed words: 1.0 or 0.0)."""
        evidence = evidence or {}
        soft = soft or {}
        phi, _, idx = self._weights(evidence, soft)
        total = float(phi.sum())
        self.check_total(total, evidence, soft)
        present = self.present_nd[(slice(None), *idx)].reshape(len(self.words), -1)
        probs = present @ phi.reshape(-1) / total
        out = dict(zip(self.words, probs.tolist(), strict=True))
        for name, value in evidence.items():
            if name not in self.axis:
                out[self.variables[name].word] = float(self.variables[name].index(value) == 1)
        for name in soft:
            if name not in self.axis:  # its own soft factor is in phi: query it exactly
                p = self.posterior([name], evidence, soft).table[1]
                out[self.variables[name].word] = float(p)
        return out
