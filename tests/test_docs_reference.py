"""The site's generated pages cover the code, follow it with no edit, and build only if whole.

docs/gen_reference.py writes the command-line, message, API and performance pages at every build
(mkdocs-gen-files); these tests build their text the same way and check what it holds. The
strict build itself runs in `make docs` (and `make test`); here it is shown to fail on a broken
link, on a copy of the site.
"""

from __future__ import annotations

import argparse
import json
import re
import runpy
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from close_numbers import RELATIVE, assert_close

from beyond_self import cli
from beyond_self.schemas import codec, keys

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def gen() -> dict[str, Any]:
    return runpy.run_path(str(REPO / "docs" / "gen_reference.py"), run_name="gen_reference")


def _walk(
    parser: argparse.ArgumentParser, path: list[str]
) -> list[tuple[list[str], argparse.ArgumentParser]]:
    found = [(path, parser)]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found += _walk(sub, [*path, name])
    return found


def _section(text: str, heading: str) -> str:
    """The part of the page from `heading` to the next heading of a command."""
    start = text.index(heading)
    end = text.find("\n## `beyond ", start + len(heading))
    return text[start : end if end != -1 else len(text)]


def test_every_command_subcommand_and_option_is_in_the_cli_reference(gen: dict[str, Any]) -> None:
    text = gen["cli_reference"]()
    parsers = gen["command_parsers"]()
    assert set(parsers) == set(cli.COMMANDS)  # every command module loads
    for name, parser in parsers.items():
        section = _section(text, f"## `beyond {name}`")
        for path, sub in _walk(parser, ["beyond", name]):
            assert f"`{' '.join(path)}`" in section, path
            for action in sub._actions:
                if isinstance(action, argparse._HelpAction | argparse._SubParsersAction):
                    continue
                for option in action.option_strings:  # `--top` or `--top N`
                    assert re.search(f"`{re.escape(option)}[` ]", section), (path, option)
                if not action.option_strings:
                    assert f"`{action.metavar or action.dest}`" in section, (path, action.dest)


def test_every_environment_variable_is_in_the_cli_reference(gen: dict[str, Any]) -> None:
    from beyond_self.runtime.bus.config import ENV_VARS

    text = _section(gen["cli_reference"](), "## Environment variables")
    for name in ENV_VARS:
        assert f"| `{name}` |" in text, name


def test_removing_an_option_from_a_parser_removes_it_from_the_reference(
    gen: dict[str, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    from beyond_self.commands import demo

    before = _section(gen["cli_reference"](), "## `beyond demo`")
    assert "`--top TOP`" in before
    original = demo.add_arguments

    def without_top(parser: argparse.ArgumentParser) -> None:
        add = parser.add_argument

        def add_unless_top(*names: str, **kwargs: Any) -> Any:
            return None if "--top" in names else add(*names, **kwargs)

        monkeypatch.setattr(parser, "add_argument", add_unless_top)
        original(parser)

    monkeypatch.setattr(demo, "add_arguments", without_top)
    after = _section(gen["cli_reference"](), "## `beyond demo`")
    assert "`--top" not in after
    assert "`--network`" in after


def test_every_message_type_and_key_is_in_the_message_reference(gen: dict[str, Any]) -> None:
    text = gen["messages_reference"]()
    for name, cls in codec.REGISTRY.items():
        assert f"### `{name}` {{#{name.lower()}}}" in text, name
        assert f"`{codec.wire_encoding(cls)}`" in text, name
        for field in cls.__struct_fields__:
            assert f"| `{field}` |" in text, (name, field)
    for suffix, _cls in keys.STREAMS.values():
        assert f"`beyond/<robot>/{suffix}`" in text, suffix
    for suffix in (keys.ASK, keys.HEALTH, keys.ALIVE, keys.PROGRESS, keys.LEDGER):
        assert f"`beyond/<robot>/{suffix}" in text, suffix


def test_the_exported_schemas_are_served_beside_the_reference(gen: dict[str, Any]) -> None:
    pages = gen["pages"]()
    for cls in codec.REGISTRY.values():
        for where in ("", "recording/"):
            schema = json.loads(pages[f"reference/schemas/{where}{cls.schema_name()}.json"])
            assert schema["type"] == "object", cls
    assert "application/msgpack" in str(pages["reference/schemas/index.md"])


def test_the_api_pages_list_every_public_module(gen: dict[str, Any]) -> None:
    for package in ("runtime", "cognition"):
        page = gen["api_page"](package, "t", "i")
        for path in (REPO / package).rglob("*.py"):
            if path.name.startswith("_") and path.name != "__init__.py":
                continue
            parts = path.relative_to(REPO).with_suffix("").parts
            module = ".".join(["beyond_self", *parts]).removesuffix(".__init__")
            assert f"::: {module}\n" in page, module


def test_the_performance_page_is_made_from_every_results_file(gen: dict[str, Any]) -> None:
    files = gen["results_files"]()
    assert len(files) >= 10
    page = gen["performance_page"]()
    for path in files:
        data = json.loads(path.read_text(encoding="utf-8"))
        assert set(data) >= {"script", "date", "machine", "provenance", "result", "table"}, path
        assert (REPO / data["script"]).is_file(), path
        assert f"`{path.relative_to(REPO)}`" in page
        assert data["table"], path
    # a figure a row names is read from the results file, not typed into the page
    gestures = json.loads((REPO / "bench" / "results" / "gestures.json").read_text())
    assert f"{gestures['result']['streaming_us_per_frame']} µs" in page


def test_a_goal_is_marked_from_the_figure(gen: dict[str, Any]) -> None:
    met = gen["_met"]
    assert met({"value": "{r[x]}", "min": 300}, {"x": 301}) == "✓"
    assert met({"value": "{r[x]}", "min": 300}, {"x": 299}) == "✗"
    assert met({"value": "{r[y][z]!m}", "max": 30}, {"y": {"z": 0.031}}) == "✗"


def test_the_sizing_section_scales_what_one_more_robot_costs(gen: dict[str, Any]) -> None:
    limit = {
        "robots": 40,
        "lower_bound": False,
        "description_p99_ms": 20.5,
        "cores_per_added_robot": 0.02,
        "mb_per_added_robot": 1.5,
        "cpu_ratio": 3.0,
    }
    result = {"limits": {"own": limit}, "fleet": [{"rss_mb": 150.0}]}
    text = "\n".join(gen["sizing_section"](result))
    row = next(line for line in text.splitlines() if line.startswith("| a person each"))
    assert "| 40 (p99 20.5 ms) | 0.02 | 50 | 150 MB | 1.5 MB | 3.0 |" in row
    assert "a burst" not in text  # a case the bench did not search has no row
    assert gen["sizing_section"]({"limits": {}}) == []
    page = gen["performance_page"]()  # the committed results give the page its section
    assert "## Sizing a workstation" in page


@pytest.mark.numeric
def test_the_science_figures_are_what_beyond_reproduce_writes(
    shared_data: Path, tmp_path: Path
) -> None:
    """Every figure of the committed results.json, as a fresh run on this machine computes it:
    the same keys, sentences and counts, each float within close_numbers' tolerance (another
    CPU or BLAS kernel changes the last digits; the article's own tolerances are checked in
    tests/test_reproduction.py)."""
    out = tmp_path / "repro"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "beyond_self",
            "reproduce",
            "--data",
            str(shared_data),
            "-o",
            str(out),
        ],
        check=True,
        capture_output=True,
        timeout=240,
    )
    committed = REPO / "docs" / "science" / "figures"
    fresh = json.loads((out / "results.json").read_text(encoding="utf-8"))
    assert_close(
        fresh,
        json.loads((committed / "results.json").read_text(encoding="utf-8")),
        f"results.json against docs/science/figures (relative {RELATIVE:g})",
    )
    for png in committed.glob("*.png"):
        assert (out / png.name).is_file(), png.name


@pytest.mark.slow
def test_the_strict_build_fails_on_a_broken_link(tmp_path: Path) -> None:
    site = tmp_path / "repo"
    shutil.copytree(REPO / "docs", site / "docs")
    shutil.copy(REPO / "mkdocs.yml", site / "mkdocs.yml")
    for name in ("bench",):
        shutil.copytree(REPO / name / "results", site / name / "results")
    page = site / "docs" / "concepts" / "fleets.md"
    page.write_text(page.read_text() + "\n[gone](no-such-page.md)\n", encoding="utf-8")
    env = {"NO_MKDOCS_2_WARNING": "1", "DISABLE_MKDOCS_2_WARNING": "true", "PATH": ""}
    mkdocs = Path(sys.executable).parent / "mkdocs"
    build = subprocess.run(
        [str(mkdocs), "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=site,
        env=env,
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert build.returncode != 0
    warnings = [line for line in build.stderr.splitlines() if line.startswith("WARNING")]
    assert len(warnings) == 1 and "no-such-page.md" in warnings[0], build.stderr


def _rendered_text(markdown_text: str) -> str:
    """The text a reader sees of a generated page: rendered as the site renders it (the site's
    Markdown extensions), tags dropped, entities read; a table row on a line, cells by ` | `."""
    import html
    from html.parser import HTMLParser

    import markdown

    rendered = markdown.markdown(markdown_text, extensions=["tables", "attr_list", "md_in_html"])

    class Text(HTMLParser):
        def __init__(self) -> None:
            super().__init__(convert_charrefs=True)
            self.parts: list[str] = []

        def handle_data(self, data: str) -> None:
            self.parts.append(data.strip("\n"))

        def handle_endtag(self, tag: str) -> None:
            self.parts.append({"td": " | ", "th": " | ", "tr": "\n", "p": "\n"}.get(tag, ""))

    reader = Text()
    reader.feed(rendered)
    return html.unescape("".join(reader.parts))


def test_keys_and_types_read_as_written_on_every_generated_page(gen: dict[str, Any]) -> None:
    """`<robot>` is text, not an HTML tag: no page shows `beyond//gesture/posterior`."""
    pages = {p: t for p, t in gen["pages"]().items() if p.endswith(".md") and isinstance(t, str)}
    assert "reference/messages.md" in pages and "reference/cli.md" in pages
    for path, page in pages.items():
        assert "beyond//" not in _rendered_text(page), path
    messages = _rendered_text(pages["reference/messages.md"])
    assert "beyond/<robot>/gesture/posterior" in messages
    # Ledger travels on its own key, not on the reasoner's query
    ledger = next(line for line in messages.splitlines() if line.startswith("Ledger | "))
    assert "beyond/<robot>/ledger/<service>" in ledger and "affordance/ask" not in ledger


def test_schemas_list_gives_each_type_its_key(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["schemas", "list"]) == 0
    rows = {line.split()[0]: line for line in capsys.readouterr().out.splitlines() if line}
    assert "beyond/<robot>/ledger/<service>" in rows["Ledger"]
    assert "affordance/ask" not in rows["Ledger"]
    assert "beyond/<robot>/affordance/ask" in rows["AffordanceQuery"]
    assert "beyond/<robot>/progress/<service>" in rows["Progress"]
    assert keys.type_for_key("beyond/robot/ledger/reasoner").type_name() == "Ledger"  # type: ignore[union-attr]
