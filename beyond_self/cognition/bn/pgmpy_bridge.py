"""The network as a pgmpy model, and pgmpy's exact inference as the reference our compiled
inference must agree with (tested, benchmarked).

A network with proper word columns is a pgmpy DiscreteBayesianNetwork. One with all-zero columns
(unseen="zero") is not a Bayesian network for pgmpy, so it becomes a DiscreteMarkovNetwork of the
CPTs exactly as they are: VariableElimination's plain factor product then drops the zero columns'
configurations, as the toolbox did. Soft evidence is pgmpy's virtual evidence (scaled to a
maximum of 1, and a fresh inference object per query, since pgmpy rewrites it in place); on a
Markov network, one more factor on a copy of the network.
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

with warnings.catch_warnings():  # pgmpy 1.1 warns, at import, about its own deprecated module
    warnings.simplefilter("ignore", FutureWarning)
    from pgmpy.factors.discrete import DiscreteFactor, TabularCPD
    from pgmpy.inference import VariableElimination
    from pgmpy.models import DiscreteBayesianNetwork, DiscreteMarkovNetwork

from beyond_self.cognition.bn.inference import Posterior, check_likelihood
from beyond_self.cognition.bn.model import BayesNet


def to_pgmpy(model: BayesNet) -> DiscreteBayesianNetwork | DiscreteMarkovNetwork:
    """Same nodes, arcs, state names and CPTs (pgmpy columns = parent configurations); a Markov
    network of the same tables when some word columns are all zero (module docstring)."""
    if model.zero_columns:
        return to_pgmpy_factors(model)
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


def to_pgmpy_factors(model: BayesNet) -> DiscreteMarkovNetwork:
    """One factor per node, its CPT as it is over (parents..., node); each family a clique."""
    network = DiscreteMarkovNetwork()
    network.add_nodes_from(model.variables)
    values = model.values
    factors = []
    for name in model.variables:
        family = [*model.parents[name], name]
        network.add_edges_from(itertools.combinations(family, 2))
        factors.append(
            DiscreteFactor(
                family,
                [len(values[n]) for n in family],
                model.cpts[name],
                state_names={n: list(values[n]) for n in family},
            )
        )
    network.add_factors(*factors)
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
    markov = isinstance(network, DiscreteMarkovNetwork)
    if soft and markov:
        network = network.copy()
        network.add_factors(*likelihood_factors(model, soft))
    if soft or inference is None:
        inference = VariableElimination(network)
    factor = inference.query(
        variables=list(query),
        evidence=evidence or None,
        virtual_evidence=(virtual_evidence(model, soft) if not markov else None) or None,
        show_progress=False,
    )
    values = model.values
    table = np.empty(tuple(len(values[q]) for q in query))
    for index in np.ndindex(*table.shape):
        assignment = {q: values[q][i] for q, i in zip(query, index, strict=True)}
        table[index] = factor.get_value(**assignment)
    if markov:  # pgmpy returns a Markov network's factor product unnormalised
        table = table / table.sum()
    return Posterior(tuple(query), tuple(values[q] for q in query), table)


def likelihood_factors(
    model: BayesNet, soft: Mapping[str, Sequence[float]]
) -> list[DiscreteFactor]:
    """Soft evidence as factors for a Markov network: each likelihood vector over its variable."""
    out = []
    for name, likelihood in soft.items():
        var = model.definition[name]
        out.append(
            DiscreteFactor(
                [name],
                [var.card],
                check_likelihood(var, likelihood),
                state_names={name: list(var.values)},
            )
        )
    return out
