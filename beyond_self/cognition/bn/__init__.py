"""The Affordance–Words Bayesian network: readers, structure and parameter learning, inference.

What other modules call: `load_definition`, `load_bag`, `synthetic_dataset`, `learn_network`
(K2 + BIC structure, BDeu/ML parameters), `save_model`/`load_model` (versioned JSON, no pickle),
and a model's `query` and `word_probabilities` (exact, compiled numpy). README.md in this folder
describes the model file. Importing this package does not import pgmpy (slow);
`cognition.bn.pgmpy_bridge` does.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from beyond_self.cognition.bn.bag import Dataset, load_bag, parse_bag
from beyond_self.cognition.bn.definition import (
    NetworkDefinition,
    Variable,
    load_definition,
    parse_definition,
)
from beyond_self.cognition.bn.inference import Posterior
from beyond_self.cognition.bn.model import BayesNet, learn_network, load_model, save_model

if TYPE_CHECKING:
    from pathlib import Path

__all__ = [
    "BayesNet",
    "Dataset",
    "NetworkDefinition",
    "Posterior",
    "Variable",
    "learn_network",
    "load_bag",
    "load_definition",
    "load_model",
    "parse_bag",
    "parse_definition",
    "save_model",
    "synthetic_dataset",
    "synthetic_paths",
]


def synthetic_dataset() -> Dataset:
    """The bundled synthetic training set (see cognition.bn.synthetic)."""
    from beyond_self.cognition.bn import (
        synthetic,  # not at import time: `python -m` runs that module
    )

    return synthetic.synthetic_dataset()


def synthetic_paths() -> tuple[Path, Path]:
    """The bundled synthetic (definition, bag table) files."""
    from beyond_self.cognition.bn import synthetic

    return synthetic.synthetic_paths()
