"""The network definition: which nodes exist, their values, and the K2 node order.

File format (`networkDefinition.txt` of Salvi et al. 2012): one line per node, the node name then
its value names, separated by white space (the original uses tabs). Line order is the K2 order.
Affordance nodes come first; a *word node* is one whose values are exactly `-` (absent) and one
other name (the word, present). Word nodes are leaves of the network and may only have affordance
parents, so the definition must list every affordance node before the first word node.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

from beyond_self.core.errors import InputError, read_text, unknown

ABSENT = "-"


@dataclass(frozen=True)
class Variable:
    """A discrete node: its name and its value names, in file order (index = code)."""

    name: str
    values: tuple[str, ...]

    @property
    def card(self) -> int:
        return len(self.values)

    @property
    def is_word(self) -> bool:
        return len(self.values) == 2 and self.values[0] == ABSENT and self.values[1] != ABSENT

    @property
    def word(self) -> str:
        """The word a word node stands for (its present value)."""
        if not self.is_word:
            raise InputError(f"node {self.name!r} is not a word node (values: {self.values})")
        return self.values[1]

    def index(self, value: str) -> int:
        try:
            return self.values.index(value)
        except ValueError:
            raise unknown(f"value of {self.name}", value, self.values) from None


@dataclass(frozen=True)
class NetworkDefinition:
    """All nodes in K2 order: the affordance part first, then the word nodes."""

    variables: tuple[Variable, ...]
    _index: dict[str, int] = field(init=False, repr=False, compare=False)
    _values: Mapping[str, tuple[str, ...]] = field(init=False, repr=False, compare=False)
    _names: tuple[str, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        index: dict[str, int] = {}
        for i, var in enumerate(self.variables):
            if var.name in index:
                raise InputError(f"duplicate node {var.name!r} in the network definition")
            index[var.name] = i
        object.__setattr__(self, "_index", index)
        # read on every frame a reasoner fuses: built once, read-only
        values = {v.name: v.values for v in self.variables}
        object.__setattr__(self, "_values", MappingProxyType(values))
        object.__setattr__(self, "_names", tuple(values))
        kinds = [v.is_word for v in self.variables]
        if True in kinds and False in kinds[kinds.index(True) :]:
            late = self.variables[kinds.index(True) + kinds[kinds.index(True) :].index(False)]
            raise InputError(
                f"affordance node {late.name!r} comes after a word node; the definition must "
                "list every affordance node before the first word node"
            )

    @property
    def names(self) -> tuple[str, ...]:
        return self._names

    @property
    def values(self) -> Mapping[str, tuple[str, ...]]:
        """Each node's values, by node name."""
        return self._values

    @property
    def affordance(self) -> tuple[Variable, ...]:
        return tuple(v for v in self.variables if not v.is_word)

    @property
    def words(self) -> tuple[Variable, ...]:
        return tuple(v for v in self.variables if v.is_word)

    @property
    def cards(self) -> tuple[int, ...]:
        return tuple(v.card for v in self.variables)

    def index(self, name: str) -> int:
        try:
            return self._index[name]
        except KeyError:
            raise unknown("variable", name, self.names) from None

    def __contains__(self, name: object) -> bool:
        return name in self._index

    def __getitem__(self, name: str) -> Variable:
        return self.variables[self.index(name)]

    def to_text(self) -> str:
        """The file format: tab separated, one node per line, trailing newline."""
        return "".join("\t".join((v.name, *v.values)) + "\n" for v in self.variables)

    def write(self, path: str | Path) -> None:
        Path(path).write_text(self.to_text(), encoding="utf-8")


def parse_definition(text: str, source: str = "<definition>") -> NetworkDefinition:
    """Parse the definition format; errors name `source`, the line and the offending column."""
    variables: list[Variable] = []
    seen: dict[str, int] = {}
    for lineno, line in enumerate(text.splitlines(), 1):
        fields = line.split()
        if not fields:
            continue
        name, values = fields[0], tuple(fields[1:])
        where = f"{source}:{lineno}"
        if name in seen:
            raise InputError(
                f"{where}: column 1: duplicate node {name!r} (first defined on line {seen[name]})"
            )
        if len(values) < 2:
            raise InputError(
                f"{where}: node {name!r} has {len(values)} value(s); a node needs at least 2 "
                "(line format: NAME VALUE1 VALUE2 ...)"
            )
        for col, value in enumerate(values, 2):
            if values.index(value) != col - 2:
                raise InputError(f"{where}: column {col}: value {value!r} of {name!r} repeated")
        seen[name] = lineno
        variables.append(Variable(name, values))
    if not variables:
        raise InputError(f"{source}: no nodes; expected lines of 'NAME VALUE1 VALUE2 ...'")
    try:
        return NetworkDefinition(tuple(variables))
    except InputError as exc:
        raise InputError(f"{source}: {exc}") from None


def load_definition(path: str | Path) -> NetworkDefinition:
    path = Path(path)
    text = read_text(path, "network definition")
    return parse_definition(text, str(path))
