"""The package's import graph, as an import-graph tool draws it: no cycles, layers one way.

Every import among `beyond_self`'s modules is an arrow: at any depth (one inside a function runs
later, not never) and under `if TYPE_CHECKING:` too (it runs for mypy only, but a reader and a
graph tool see the two modules tied all the same). `from a import b` points at the module `a.b`
where there is one, else at `a`. A package is not drawn as importing its submodules' parents:
importing `a.b` runs `a/__init__.py`, which holds no imports of its own here, or few.
"""

from __future__ import annotations

import ast
from collections.abc import Iterable, Mapping
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "beyond_self"

# Who may import whom, lowest first: a module imports only from its own layer or those below.
# The commands, the command line and the terminal views sit on top, over everything.
LAYERS = ("core", "schemas", "cognition", "runtime", "services")


def module_names(root: Path) -> dict[str, Path]:
    """Dotted name of every module below `root` (a package folder), its file."""
    found = {}
    for path in sorted(root.rglob("*.py")):  # rglob does not follow the links at the top
        parts = path.relative_to(root.parent).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        found[".".join(parts)] = path
    return found


def _target(name: str, modules: Mapping[str, Path]) -> str | None:
    """The module of ours an imported dotted name stands for: itself or its nearest parent."""
    while name:
        if name in modules:
            return name
        name = name.rpartition(".")[0]
    return None


def imports_of(module: str, path: Path, modules: Mapping[str, Path]) -> set[str]:
    """The modules of ours that `module` imports anywhere in its file."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                base = ".".join([*anchor, *([base] if base else [])])
            names = [f"{base}.{alias.name}" for alias in node.names]
            names = [n if n in modules else base for n in names]
        for name in names:
            target = _target(name, modules)
            if target is not None and target != module:
                found.add(target)
    return found


def graph(root: Path) -> dict[str, set[str]]:
    modules = module_names(root)
    return {name: imports_of(name, path, modules) for name, path in modules.items()}


def tangles(edges: Mapping[str, Iterable[str]]) -> list[set[str]]:
    """Each group of modules that reach one another: a strongly connected component of more
    than one module."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    groups: list[set[str]] = []

    def visit(start: str) -> None:  # Tarjan's, iterative: the graph may be deep
        work = [(start, iter(sorted(edges.get(start, ()))))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(edges.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                group = set()
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    group.add(member)
                    if member == node:
                        break
                if len(group) > 1:
                    groups.append(group)

    for node in sorted(edges):
        if node not in index:
            visit(node)
    return groups


def cycles(edges: Mapping[str, Iterable[str]]) -> list[list[str]]:
    """One cycle through each tangle: the shortest way back to its first module."""
    return [_loop(min(group), group, edges) for group in tangles(edges)]


def _loop(first: str, group: set[str], edges: Mapping[str, Iterable[str]]) -> list[str]:
    """The shortest path from `first` back to itself inside `group` (breadth first)."""
    came_from: dict[str, str] = {}
    frontier = [first]
    while frontier:
        following = []
        for node in frontier:
            for child in sorted(edges.get(node, ())):
                if child not in group or child in came_from:
                    continue
                came_from[child] = node
                if child == first:
                    path = [first]
                    while path[-1] != first or len(path) == 1:
                        path.append(came_from[path[-1]])
                    return path[::-1]
                following.append(child)
        frontier = following
    raise AssertionError(f"{first} is in a cycle it cannot reach again")  # pragma: no cover


def layer(module: str) -> int | None:
    """Where a module stands in LAYERS, or None for what sits over them (commands, cli, ...)."""
    parts = module.split(".")
    return LAYERS.index(parts[1]) if len(parts) > 1 and parts[1] in LAYERS else None


def upward(edges: Mapping[str, Iterable[str]]) -> list[str]:
    """Every import of a layer's module from a layer above it, or from over all of them."""
    found = []
    for module, targets in sorted(edges.items()):
        mine = layer(module)
        if mine is None:
            continue
        for target in sorted(targets):
            theirs = layer(target)
            if theirs is None or theirs > mine:
                found.append(f"{module} imports {target}")
    return found


def test_the_walk_reads_the_package_at_its_import_paths() -> None:
    modules = module_names(PACKAGE)
    assert modules["beyond_self.runtime.service"] == PACKAGE / "runtime" / "service.py"
    assert modules["beyond_self.runtime"] == PACKAGE / "runtime" / "__init__.py"
    assert len(modules) > 150
    edges = graph(PACKAGE)
    assert "beyond_self.runtime.bus.session" in edges["beyond_self.runtime.service"]


def test_the_package_has_no_import_cycles() -> None:
    edges = graph(PACKAGE)
    found = [
        " -> ".join(_loop(min(group), group, edges)) + f" (modules in the tangle: {len(group)})"
        for group in tangles(edges)
    ]
    assert not found, "import cycles:\n" + "\n".join(found)


def test_layers_import_only_downwards() -> None:
    found = upward(graph(PACKAGE))
    assert not found, f"imports up the layers {LAYERS}:\n" + "\n".join(found)


def test_the_check_sees_every_kind_of_import(tmp_path: Path) -> None:
    """A cycle made by a function-level import, one by a TYPE_CHECKING import and one by a
    relative import are each found; a package importing its own submodule is not a cycle."""
    root = tmp_path / "pkg"
    (root / "sub").mkdir(parents=True)
    files = {
        "__init__.py": "",
        "a.py": "def f() -> None:\n    from pkg import b\n",
        "b.py": "import pkg.a\n",
        "c.py": "import typing\n\nif typing.TYPE_CHECKING:\n    from pkg.sub.d import X\n",
        "sub/__init__.py": "from pkg.sub import d\n",
        "sub/d.py": "from .. import c\nX = 1\n",
        "e.py": "import json\nfrom pkg.sub import d\n",
    }
    for name, text in files.items():
        (root / name).write_text(text)
    edges = graph(root)
    assert edges["pkg.e"] == {"pkg.sub.d"}
    assert edges["pkg.sub"] == {"pkg.sub.d"}
    assert sorted(cycles(edges)) == [["pkg.a", "pkg.b", "pkg.a"], ["pkg.c", "pkg.sub.d", "pkg.c"]]


def test_the_check_sees_an_import_up_the_layers() -> None:
    edges = {
        "beyond_self.cognition.scene": {"beyond_self.runtime.clock", "beyond_self.core.errors"},
        "beyond_self.schemas.base": {"beyond_self.core.errors"},
        "beyond_self.runtime.fleet": {"beyond_self.commands.up"},
        "beyond_self.commands.up": {"beyond_self.services.deployment"},
    }
    assert upward(edges) == [
        "beyond_self.cognition.scene imports beyond_self.runtime.clock",
        "beyond_self.runtime.fleet imports beyond_self.commands.up",
    ]
