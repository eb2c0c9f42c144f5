"""Every third-party module our code imports is declared in pyproject.toml.

An import that works only because some other dependency happens to bring the package along
breaks the day that dependency drops it, and a fresh install from pyproject.toml is then the
first to notice. Imports inside functions count too: they fail later, not never.
"""

from __future__ import annotations

import ast
import re
import sys
import tomllib
from collections.abc import Iterable, Iterator
from importlib.metadata import packages_distributions
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("beyond_self", "cognition", "core", "runtime", "schemas", "services", "bench", "tests")


def _normalise(name: str) -> str:
    """PEP 503: `Foo_bar.baz` and `foo-bar-baz` are the same distribution."""
    return re.sub(r"[-_.]+", "-", name).lower()


def declared() -> set[str]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    requirements = list(project.get("dependencies", []))
    for extra in project.get("optional-dependencies", {}).values():
        requirements += extra
    names = set()
    for requirement in requirements:
        match = re.match(r"[A-Za-z0-9][A-Za-z0-9._-]*", requirement)
        assert match, f"pyproject.toml: cannot read the name in {requirement!r}"
        names.add(_normalise(match.group()))
    return names


def imports(path: Path) -> Iterator[tuple[str, int]]:
    """(top-level module, line) of every absolute import in the file, at any depth."""
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name.split(".")[0], node.lineno
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.module.split(".")[0], node.lineno


def ours(module: str, importer: Path) -> bool:
    """A package of this repository, a helper module beside the importing file (tests and
    their examples import their siblings), or one of the tests' helpers (the benchmarks load the
    machine as the tests do)."""
    return any(
        (folder / module).is_dir() or (folder / f"{module}.py").is_file()
        for folder in (ROOT, importer.parent, ROOT / "tests")
    )


def sources() -> Iterator[Path]:
    """Every module of ours but the real rclpy nodes, which import ROS 2's wheels in the side
    environment the ROS 2 tests make (their requirement list is there, not in pyproject.toml)."""
    for package in PACKAGES:
        yield from sorted(p for p in (ROOT / package).rglob("*.py") if "rclpy_nodes" not in p.parts)


def undeclared(paths: Iterable[Path]) -> list[str]:
    distributions = packages_distributions()
    known = declared()
    problems = []
    for path in paths:
        for module, line in imports(path):
            if module == "__future__" or module in sys.stdlib_module_names or ours(module, path):
                continue
            where = f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}:{line}"
            dists = distributions.get(module)
            if not dists:
                problems.append(f"{where}: {module} is not installed, so not declared")
            elif not known & {_normalise(d) for d in dists}:
                problems.append(
                    f"{where}: {module} (from {' or '.join(sorted(set(dists)))}) is not "
                    "declared in pyproject.toml"
                )
    return problems


def test_every_third_party_import_is_declared() -> None:
    problems = undeclared(sources())
    assert not problems, "\n".join(problems)


def test_the_check_sees_an_undeclared_import(tmp_path: Path) -> None:
    """An import inside a function of a module that is installed but not declared (pluggy,
    present wherever pytest runs) is reported; the stdlib, our packages and a sibling are not."""
    (tmp_path / "sibling.py").write_text("")
    source = tmp_path / "example.py"
    source.write_text(
        "import json\nimport sibling\nfrom runtime import clock\n\n"
        "def f() -> None:\n    import pluggy._hooks\n"
    )
    assert undeclared([source]) == [
        f"{source}:6: pluggy (from pluggy) is not declared in pyproject.toml"
    ]
