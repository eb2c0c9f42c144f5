"""Module docstrings say why in at most 10 lines; the essays live in the docs site.

Every module of `beyond_self/`, its layer folders (cognition, core, runtime, schemas, services)
included, is read once (the links at the repository's top point into it and are not followed).
"""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
FOLDERS = ("beyond_self", "cognition", "core", "runtime", "schemas", "services")  # top links too
MAX_LINES = 10


def modules() -> list[Path]:
    found: set[Path] = set()
    for folder in FOLDERS:
        for path in (REPO / folder).rglob("*.py"):  # rglob does not follow the links
            found.add(path.resolve())
    return sorted(found)


def docstring_lines(path: Path) -> int:
    doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8")), clean=True)
    return len(doc.strip().splitlines()) if doc else 0


def test_the_walk_reads_every_layer_once() -> None:
    found = modules()
    names = {str(p.relative_to(REPO)) for p in found}
    assert "beyond_self/cli.py" in names and "beyond_self/runtime/service.py" in names
    assert not any(n.startswith("runtime/") for n in names)
    assert len(found) > 150


def test_the_count_is_of_lines(tmp_path: Path) -> None:
    module = tmp_path / "m.py"
    module.write_text('"""One.\n\nTwo\nthree."""\n\nX = 1\n', encoding="utf-8")
    assert docstring_lines(module) == 4
    module.write_text("X = 1\n", encoding="utf-8")
    assert docstring_lines(module) == 0


def test_module_docstrings_are_at_most_ten_lines() -> None:
    long = [
        f"{path.relative_to(REPO)}: {n} lines"
        for path in modules()
        if (n := docstring_lines(path)) > MAX_LINES
    ]
    assert not long, "module docstrings over 10 lines:\n" + "\n".join(long)
