"""The learned Affordance–Words network, how it is learned, and its file format.

`learn_network` runs K2/BIC for the structure (structure.py) and counting for the parameters
(parameters.py); `BayesNet` holds the result and answers queries through the compiled numpy form
(inference.py). `save_model`/`load_model` write and read the versioned JSON format documented in
README.md beside this file: no pickle, every number readable, CPTs exact (floats round-trip).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, Literal

import numpy as np

from beyond_self.cognition.bn.bag import Dataset
from beyond_self.cognition.bn.definition import NetworkDefinition, Variable
from beyond_self.cognition.bn.inference import CompiledNetwork, Posterior
from beyond_self.cognition.bn.parameters import UNSEEN_RULES, bdeu_cpt, word_cpt
from beyond_self.cognition.bn.structure import (
    DEFAULT_MAX_PARENTS,
    DEFAULT_ROOTS,
    Scorer,
    family_counts,
    k2_search,
    log_likelihood,
)
from beyond_self.core.errors import InputError, unknown

FORMAT = "beyond-self/bn-model"
VERSION = 1


@dataclass
class BayesNet:
    """Nodes, parents, CPTs (`cpts[name].shape == (*parent cards, card)`) and training figures."""

    definition: NetworkDefinition
    parents: dict[str, tuple[str, ...]]
    cpts: dict[str, np.ndarray]
    node_log_likelihood: dict[str, float] = field(default_factory=dict)
    training: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        names = self.definition.names
        for name in names:
            if name not in self.parents or name not in self.cpts:
                raise InputError(f"model lacks parents or CPT for node {name!r}")
        for name, ps in self.parents.items():
            if name not in self.definition:
                raise unknown("node", name, names)
            for p in ps:
                if p not in self.definition or p == name:
                    raise InputError(f"node {name!r} has invalid parent {p!r}")
            shape = (*(self.definition[p].card for p in ps), self.definition[name].card)
            cpt = np.asarray(self.cpts[name], dtype=float)
            if cpt.shape != shape:
                raise InputError(f"CPT of {name!r} has shape {cpt.shape}; expected {shape}")
            sums = cpt.reshape(-1, shape[-1]).sum(axis=1)
            proper = np.isclose(sums, 1.0, atol=1e-6)
            rule = "rows sum to 1"
            if self.definition[name].is_word:  # the toolbox's unseen column (unseen="zero")
                proper |= sums == 0.0
                rule += ", or are all zero for a parent configuration ruled out"
            if np.any(cpt < 0) or not np.all(proper):
                raise InputError(f"CPT of {name!r} is not a probability table ({rule})")
            self.cpts[name] = cpt
        self._check_acyclic()

    def _check_acyclic(self) -> None:
        state: dict[str, int] = {}

        def visit(node: str) -> None:
            if state.get(node) == 1:
                raise InputError(f"the network has a cycle through {node!r}")
            if state.get(node) == 2:
                return
            state[node] = 1
            for p in self.parents[node]:
                visit(p)
            state[node] = 2

        for name in self.definition.names:
            visit(name)

    # -- description ----------------------------------------------------------------------------

    @property
    def variables(self) -> tuple[str, ...]:
        return self.definition.names

    @property
    def values(self) -> Mapping[str, tuple[str, ...]]:
        return self.definition.values

    @property
    def words(self) -> tuple[str, ...]:
        """The vocabulary: each word node's present value, in node order."""
        return tuple(v.word for v in self.definition.words)

    @property
    def zero_columns(self) -> dict[str, int]:
        """Word nodes with all-zero CPT rows (unseen="zero"), and how many each: those parent
        configurations are out of the joint, and every query renormalises over the rest."""
        out = {}
        for var in self.definition.words:
            rows = self.cpts[var.name].reshape(-1, var.card)
            zeros = int(np.count_nonzero(rows.sum(axis=1) == 0.0))
            if zeros:
                out[var.name] = zeros
        return out

    @property
    def arcs(self) -> list[tuple[str, str]]:
        """(parent, child) pairs, children in node order, parents in node order."""
        return [(p, child) for child in self.variables for p in self.parents[child]]

    def training_log_likelihood(self, exclude: Sequence[str] = DEFAULT_ROOTS) -> float:
        """The reference's L: training log-likelihood summed over all nodes but `exclude`."""
        return float(sum(ll for n, ll in self.node_log_likelihood.items() if n not in exclude))

    def log_likelihood(self, dataset: Dataset) -> dict[str, float]:
        """Per-node log-likelihood of `dataset` (same definition) under this model."""
        if dataset.definition.names != self.definition.names:
            raise InputError("dataset and model have different nodes")
        cards = self.definition.cards
        out: dict[str, float] = {}
        for i, name in enumerate(self.variables):
            ps = [self.definition.index(p) for p in self.parents[name]]
            counts = family_counts(dataset.data, cards, i, ps)
            out[name] = log_likelihood(counts, self.cpts[name].reshape(counts.shape))
        return out

    # -- inference ------------------------------------------------------------------------------

    @cached_property
    def compiled(self) -> CompiledNetwork:
        return CompiledNetwork(self.definition.variables, self.parents, self.cpts)

    def query(
        self,
        query: str | Sequence[str],
        evidence: Mapping[str, str] | None = None,
        soft: Mapping[str, Sequence[float]] | None = None,
    ) -> Posterior:
        """Exact P(query | evidence, soft evidence); several variables give their joint."""
        names = [query] if isinstance(query, str) else list(query)
        return self.compiled.posterior(names, evidence, soft)

    def word_probabilities(
        self,
        evidence: Mapping[str, str] | None = None,
        soft: Mapping[str, Sequence[float]] | None = None,
    ) -> dict[str, float]:
        """P(word present | evidence) for every word, keyed by the word."""
        return self.compiled.word_probabilities(evidence, soft)

    # -- file format ----------------------------------------------------------------------------

    def to_json(self) -> dict[str, Any]:
        nodes = []
        for var in self.definition.variables:
            cpt = self.cpts[var.name]
            node: dict[str, Any] = {
                "name": var.name,
                "values": list(var.values),
                "parents": list(self.parents[var.name]),
                "cpt": cpt.reshape(-1, var.card).tolist(),
            }
            if var.name in self.node_log_likelihood:
                node["log_likelihood"] = self.node_log_likelihood[var.name]
            nodes.append(node)
        return {"format": FORMAT, "version": VERSION, "nodes": nodes, "training": self.training}

    @classmethod
    def from_json(cls, obj: Any, source: str = "<model>") -> BayesNet:
        if not isinstance(obj, dict) or obj.get("format") != FORMAT:
            raise InputError(f"{source}: not a beyond-self network model (format {FORMAT!r})")
        if obj.get("version") != VERSION:
            raise InputError(
                f"{source}: model format version {obj.get('version')!r}; this code reads {VERSION}"
            )
        try:
            variables = tuple(Variable(n["name"], tuple(n["values"])) for n in obj["nodes"])
            definition = NetworkDefinition(variables)
            parents = {n["name"]: tuple(n["parents"]) for n in obj["nodes"]}
            cpts: dict[str, np.ndarray] = {}
            for n in obj["nodes"]:
                for p in n["parents"]:
                    if p not in definition:
                        raise unknown(f"parent of {n['name']}", p, definition.names)
                shape = (*(definition[p].card for p in n["parents"]), len(n["values"]))
                table = np.asarray(n["cpt"], dtype=float)
                if table.size != math.prod(shape):
                    raise InputError(
                        f"CPT of {n['name']!r} has {table.size} numbers; expected "
                        f"{math.prod(shape)} (shape {shape})"
                    )
                cpts[n["name"]] = table.reshape(shape)
            lls = {
                n["name"]: float(n["log_likelihood"]) for n in obj["nodes"] if "log_likelihood" in n
            }
            return cls(definition, parents, cpts, lls, dict(obj.get("training", {})))
        except InputError as exc:
            raise InputError(f"{source}: {exc}") from None
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(
                f"{source}: malformed model file ({type(exc).__name__}: {exc})"
            ) from None


def save_model(model: BayesNet, path: str | Path) -> None:
    Path(path).write_text(json.dumps(model.to_json(), indent=1) + "\n", encoding="utf-8")


def load_model(path: str | Path) -> BayesNet:
    path = Path(path)
    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(
            f"model file {path} does not exist; make one with `beyond bn learn`"
        ) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"cannot read model file {path}: {exc}") from None
    return BayesNet.from_json(obj, str(path))


def learn_parameters(
    dataset: Dataset,
    parents: Mapping[str, Sequence[str]],
    *,
    affordance_ess: float = 1.0,
    unseen: str = "absent",
    word_ess: float = 1.0,
) -> tuple[dict[str, np.ndarray], dict[str, float]]:
    """CPTs for a given structure and each node's training log-likelihood under them."""
    if unseen not in UNSEEN_RULES:
        raise unknown("rule for unseen parent configurations", unseen, UNSEEN_RULES)
    definition = dataset.definition
    cards = definition.cards
    cpts: dict[str, np.ndarray] = {}
    lls: dict[str, float] = {}
    for i, var in enumerate(definition.variables):
        ps = [definition.index(p) for p in parents[var.name]]
        counts = family_counts(dataset.data, cards, i, ps)
        table = (
            word_cpt(counts, unseen, word_ess) if var.is_word else bdeu_cpt(counts, affordance_ess)
        )
        cpts[var.name] = table.reshape(*(cards[p] for p in ps), var.card)
        lls[var.name] = log_likelihood(counts, table)
    return cpts, lls


def learn_network(
    dataset: Dataset,
    *,
    roots: Sequence[str] = DEFAULT_ROOTS,
    max_parents: int = DEFAULT_MAX_PARENTS,
    affordance_ess: float = 1.0,
    unseen: str = "absent",
    word_ess: float = 1.0,
    scorer: Literal["counts", "pgmpy"] | Scorer = "counts",
    bnt_prior: bool = False,
    structure: Mapping[str, Sequence[str]] | None = None,
    on_node: Callable[[str, tuple[str, ...]], None] | None = None,
) -> BayesNet:
    """Learn structure (K2 + BIC, unless `structure` is given) and parameters from `dataset`."""
    if structure is None:
        parents = k2_search(
            dataset,
            roots=roots,
            max_parents=max_parents,
            scorer=scorer,
            bnt_prior=bnt_prior,
            on_node=on_node,
        )
    else:
        parents = {n: tuple(structure.get(n, ())) for n in dataset.definition.names}
    cpts, lls = learn_parameters(
        dataset, parents, affordance_ess=affordance_ess, unseen=unseen, word_ess=word_ess
    )
    training = {
        "source": dataset.source,
        "rows": dataset.rows,
        "structure": "given" if structure is not None else "k2-bic",
        "roots": list(roots),
        "max_parents": max_parents,
        "affordance_prior": {"type": "bdeu", "ess": affordance_ess},
        "word_prior": (
            {"type": "bdeu", "ess": word_ess} if unseen == "dirichlet" else {"type": "ml"}
        ),
        "unseen": unseen,
    }
    return BayesNet(dataset.definition, parents, cpts, lls, training)
