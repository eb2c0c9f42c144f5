"""The network as a pgmpy DiscreteBayesianNetwork, and pgmpy's exact inference as the reference.

pgmpy is the container other tools understand and the yardstick for our compiled inference:
`reference_query` must agree with `BayesNet.query` to rounding error (tested, benchmarked).

Soft evidence goes in as pgmpy's virtual evidence (pgmpy 1.x `VariableElimination.query(...,
virtual_evidence=[TabularCPD])`): pgmpy adds a binary child `__VAR` with
P(__VAR = 0 | VAR) = the given vector, observed at 0, so the vector acts as a likelihood. Because
it is used as a probability column, we scale it to a maximum of 1 first (a likelihood's scale does
not matter). pgmpy rebuilds the inference object around the augmented model in place, so every
soft query here gets a fresh VariableElimination.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

with warnings.catch_warnings():  # pgmpy 1.1 warns, at import, about its own deprecated module
    warnings.simplefilter("ignore", FutureWarning)
    from pgmpy.factors.discrete import TabularCPD
    from pgmpy.inference import VariableElimination
    from pgmpy.models import DiscreteBayesianNetwork

from beyond_self.cognition.bn.inference import Posterior, check_likelihood
from beyond_self.cognition.bn.model import BayesNet


def to_pgmpy(model: BayesNet) -> DiscreteBayesianNetwork:
    """Same nodes, arcs, state names and CPTs (pgmpy columns = parent configurations)."""
    network = DiscreteBayesianNetwork()
    network.add_nodes_from(model.variables)
    network.add_edges_from(model.arcs)
    values = model.values
    cpds = []
    for name in model.variables:
        ps = list(model.parents[name])
        cpt = model.cpts[name]
        card = cpt.shape[-1]
        cpds.append(
            TabularCPD(
                variable=name,
                variable_card=card,
                values=cpt.reshape(-1, card).T,
                evidence=ps or None,
                evidence_card=[len(values[p]) for p in ps] or None,
                state_names={n: list(values[n]) for n in (name, *ps)},
            )
        )
    network.add_cpds(*cpds)
    return network


def virtual_evidence(model: BayesNet, soft: Mapping[str, Sequence[float]]) -> list[TabularCPD]:
    out = []
    for name, likelihood in soft.items():
        var = model.definition[name]
        vec = check_likelihood(var, likelihood)
        vec = vec / vec.max()
        out.append(
            TabularCPD(
                variable=name,
                variable_card=var.card,
                values=vec.reshape(-1, 1),
                state_names={name: list(var.values)},
            )
        )
    return out


def reference_query(
    network: DiscreteBayesianNetwork,
    model: BayesNet,
    query: Sequence[str],
    evidence: Mapping[str, str] | None = None,
    soft: Mapping[str, Sequence[float]] | None = None,
    inference: Any = None,
) -> Posterior:
    """P(query | evidence) by pgmpy's VariableElimination, as a Posterior in query order.

    `inference` may be a reused VariableElimination for queries without soft evidence.
    """
    evidence = dict(evidence or {})
    soft = dict(soft or {})
    if soft or inference is None:
        inference = VariableElimination(network)
    factor = inference.query(
        variables=list(query),
        evidence=evidence or None,
        virtual_evidence=virtual_evidence(model, soft) or None,
        show_progress=False,
    )
    values = model.values
    table = np.empty(tuple(len(values[q]) for q in query))
    for index in np.ndindex(*table.shape):
        assignment = {q: values[q][i] for q, i in zip(query, index, strict=True)}
        table[index] = factor.get_value(**assignment)
    return Posterior(tuple(query), tuple(values[q] for q in query), table)
