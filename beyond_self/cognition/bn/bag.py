"""The bag-of-words table: one training row per spoken description, integer coded.

File format (`sent-1-5_lab_aff_bag.txt` of Salvi et al. 2012): tab separated; a header row naming
the nodes, then one row per description with one value name per node. Word columns hold `-` when
the word was not said and the word itself when it was. Columns may come in any order; every node
of the definition must appear exactly once.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from beyond_self.cognition.bn.definition import NetworkDefinition
from beyond_self.core.errors import InputError, read_text


@dataclass(frozen=True)
class Dataset:
    """Rows of value codes: `data[row, node]` indexes `definition.variables[node].values`."""

    definition: NetworkDefinition
    data: np.ndarray  # (rows, nodes), int64
    source: str = "<memory>"

    def __post_init__(self) -> None:
        data = np.asarray(self.data)
        n_nodes = len(self.definition.variables)
        if data.ndim != 2 or data.shape[1] != n_nodes:
            raise InputError(f"dataset must have shape (rows, {n_nodes}); got {data.shape}")
        cards = np.asarray(self.definition.cards)
        if data.size and (data.min() < 0 or np.any(data.max(axis=0) >= cards)):
            raise InputError("dataset holds a value code outside its node's values")
        object.__setattr__(self, "data", data.astype(np.int64, copy=False))

    @property
    def rows(self) -> int:
        return int(self.data.shape[0])

    def column(self, name: str) -> np.ndarray:
        return self.data[:, self.definition.index(name)]

    def to_text(self) -> str:
        """The file format: header of node names, then value names; tab separated."""
        names = [v.values for v in self.definition.variables]
        lines = ["\t".join(self.definition.names)]
        for row in self.data:
            lines.append("\t".join(names[j][code] for j, code in enumerate(row)))
        return "\n".join(lines) + "\n"

    def write(self, path: str | Path) -> None:
        Path(path).write_text(self.to_text(), encoding="utf-8")


def parse_bag(text: str, definition: NetworkDefinition, source: str = "<bag>") -> Dataset:
    """Parse the table; errors name `source`, line, column and what the column may hold."""
    lines = text.splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    if not lines:
        raise InputError(f"{source}: empty; expected a header row naming the nodes")
    header = lines[0].rstrip("\r").split("\t")
    position: dict[str, int] = {}
    for col, name in enumerate(header, 1):
        if name not in definition:
            raise InputError(
                f"{source}:1: column {col}: unknown node {name!r}; "
                f"the network definition has: {', '.join(definition.names[:12])}, ..."
            )
        if name in position:
            raise InputError(f"{source}:1: column {col}: node {name!r} repeated")
        position[name] = col - 1
    missing = [n for n in definition.names if n not in position]
    if missing:
        raise InputError(f"{source}:1: header lacks node(s) {', '.join(missing)}")
    order = [position[n] for n in definition.names]  # file column of each definition node
    lookup = [{value: code for code, value in enumerate(v.values)} for v in definition.variables]
    data = np.empty((len(lines) - 1, len(order)), dtype=np.int64)
    for row, line in enumerate(lines[1:]):
        cells = line.rstrip("\r").split("\t")
        lineno = row + 2
        if len(cells) != len(header):
            raise InputError(
                f"{source}:{lineno}: {len(cells)} columns; the header has {len(header)} "
                "(tab separated)"
            )
        for j, col in enumerate(order):
            code = lookup[j].get(cells[col])
            if code is None:
                var = definition.variables[j]
                raise InputError(
                    f"{source}:{lineno}: column {col + 1} ({var.name}): unknown value "
                    f"{cells[col]!r}; valid: {', '.join(var.values)}"
                )
            data[row, j] = code
    return Dataset(definition, data, source)


def load_bag(path: str | Path, definition: NetworkDefinition) -> Dataset:
    path = Path(path)
    text = read_text(path, "bag-of-words table")
    return parse_bag(text, definition, str(path))
