"""The article's reference network, `BN_lab.mat` (struct `netobj_lab`), read with scipy.

Only the plain fields are readable (the CPTs sit in MATLAB objects): node names, value names, the
graph (`dag[i, j] = 1`: node i is a parent of node j), the training data (1-based codes, one
column per row of the bag table) and `L`, the training log-likelihood over the non-clamped nodes.
They are what our learning must reproduce.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from beyond_self.cognition.paths import require_shared_data
from beyond_self.core.errors import InputError

REFERENCE_FILE = "saponaro2019/BN_lab.mat"


@dataclass(frozen=True)
class ReferenceNetwork:
    names: tuple[str, ...]
    values: tuple[tuple[str, ...], ...]
    dag: np.ndarray  # (nodes, nodes) bool, dag[i, j]: i is a parent of j
    data: np.ndarray  # (rows, nodes) 0-based value codes
    log_likelihood: float  # L
    clamped: tuple[str, ...]

    def parents(self) -> dict[str, tuple[str, ...]]:
        return {
            child: tuple(self.names[i] for i in np.flatnonzero(self.dag[:, j]))
            for j, child in enumerate(self.names)
        }

    def arcs(self) -> set[tuple[str, str]]:
        return {(self.names[i], self.names[j]) for i, j in zip(*np.nonzero(self.dag), strict=True)}


def _strings(cell: Any) -> tuple[str, ...]:
    return tuple(str(np.asarray(x).ravel()[0]) for x in np.asarray(cell).ravel())


def load_reference(path: str | Path | None = None) -> ReferenceNetwork:
    """Read BN_lab.mat (default: from the shared data folder)."""
    import scipy.io

    path = Path(path) if path is not None else require_shared_data(REFERENCE_FILE)
    try:
        mat = scipy.io.loadmat(str(path))
        net = mat["netobj_lab"][0, 0]
        names = _strings(net["nodeNames"])
        values = tuple(_strings(v) for v in np.asarray(net["nodeValueNames"]).ravel())
        dag = np.asarray(net["dag"]) != 0
        data = np.asarray(net["data"], dtype=np.int64).T - 1
        loglik = float(np.asarray(net["L"]).ravel()[0])
        clamped = tuple(
            n for n, c in zip(names, np.asarray(net["clamped_nodes"]).ravel(), strict=True) if c
        )
    except (OSError, KeyError, IndexError, ValueError) as exc:
        raise InputError(f"cannot read reference network {path}: {exc}") from None
    return ReferenceNetwork(names, values, dag, data, loglik, clamped)
