"""The commands of the README and docs/ parse as written, in their current spelling, and their links
point at files that exist.

Each `beyond ...` line of a shell block is parsed by the `beyond` parser itself (not run: the
pages' runs are tests of their own, e.g. tests/test_speech_dropin.py); a usage error or a
deprecated spelling ("--out is deprecated; use -o/--output") fails here.
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from beyond_self.cli import build_parser
from beyond_self.commands.argtypes import NOTES

REPO = Path(__file__).resolve().parents[1]
PAGES = [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]
CONTROL = {"&", "&&", "|", "||", ";", ">", ">>", "<", "2>", "2>&1"}


def words(line: str) -> list[str]:
    """A command line's words up to the first shell control operator (`&`, `|`, `>`, ...)."""
    lexer = shlex.shlex(line, posix=True, punctuation_chars=True)
    lexer.whitespace_split = True
    found = []
    for word in lexer:
        if word in CONTROL:
            break
        found.append(word)
    return found


def commands(page: Path) -> list[str]:
    found = []
    for block in re.findall(r"```(?:sh|bash|shell)\n(.*?)```", page.read_text(), re.S):
        for line in block.replace("\\\n", " ").splitlines():
            line = line.split(" #", 1)[0].strip()
            if line.startswith("beyond "):
                found.append(line)
    return found


def test_the_pages_have_commands() -> None:
    assert any(commands(page) for page in PAGES)


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_command_parses_in_its_current_spelling(
    page: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)  # an output folder an option names is made here, not in docs/
    for line in commands(page):
        argv = words(line)[1:]
        if argv[0].startswith("-"):
            continue  # `beyond --version`, `beyond --help`: the top-level parser's own flags
        try:
            args = build_parser(argv[0]).parse_args(argv)
        except SystemExit:
            pytest.fail(f"{page.name}: {line!r} does not parse")
        assert not getattr(args, NOTES, None), (line, getattr(args, NOTES))


def test_every_relative_link_of_the_readme_points_at_a_file() -> None:
    """The README is outside the site, whose strict build checks the links of docs/."""
    page = REPO / "README.md"
    for target in re.findall(r"\]\(([^)#\s]+)\)", page.read_text()):
        if "://" not in target:
            assert (page.parent / target).exists(), f"{page.name}: {target}"
