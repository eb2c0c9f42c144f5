"""The site's generated pages: command line, messages and keys, Python API, performance.

mkdocs-gen-files runs this file at every build; the pages exist only in the built site, so the
reference follows the parsers, `schemas/` and `bench/results/*.json` with no edit by hand.
`tests/test_docs_reference.py` imports the same functions to check what they cover.
"""

from __future__ import annotations

import argparse
import html
import json
import re
import string
import sys
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import msgspec

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:  # a fresh clone without an install: the package from the checkout
    sys.path.insert(0, str(ROOT))

from beyond_self import cli  # noqa: E402
from beyond_self.commands import schemas_cmd  # noqa: E402
from beyond_self.runtime.bus import config  # noqa: E402
from beyond_self.schemas import codec, keys  # noqa: E402
from beyond_self.schemas.base import Message  # noqa: E402

# ---------------------------------------------------------------------------- command line


_CODE_SPAN = re.compile(r"(`[^`]*`)")


def _text(text: str) -> str:
    """Markdown prose from a docstring or help text: `<`, `>` and `&` outside code spans are
    characters, not HTML (`beyond/<robot>/...` would lose its `<robot>` as an unknown tag)."""
    parts = _CODE_SPAN.split(text)
    return "".join(p if i % 2 else html.escape(p, quote=False) for i, p in enumerate(parts))


def _cell(text: str) -> str:
    return _text(" ".join(text.split())).replace("|", "\\|")


def _flags(action: argparse.Action) -> str:
    if not action.option_strings:
        return f"`{action.metavar or action.dest}`"
    if action.nargs == 0:
        return ", ".join(f"`{o}`" for o in action.option_strings)
    metavar = action.metavar or action.dest.upper()
    if isinstance(metavar, tuple):
        metavar = " ".join(metavar)
    return ", ".join(f"`{o} {metavar}`" for o in action.option_strings)


def _default(action: argparse.Action) -> str:
    if action.nargs == 0 or action.default in (None, argparse.SUPPRESS, False, [], ()):
        return ""
    return f"`{action.default}`"


def _subparsers(parser: argparse.ArgumentParser) -> Iterator[tuple[str, argparse.ArgumentParser]]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            yield from action.choices.items()


def _options_table(parser: argparse.ArgumentParser) -> list[str]:
    rows = []
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction | argparse._SubParsersAction):
            continue
        if action.help == argparse.SUPPRESS:
            continue
        choices = ""
        if action.choices is not None:
            choices = " (one of: " + ", ".join(f"`{c}`" for c in action.choices) + ")"
        rows.append(
            f"| {_flags(action)} | {_cell(action.help or '')}{choices} | {_default(action)} |"
        )
    if not rows:
        return []
    return ["| argument | meaning | default |", "|---|---|---|", *rows, ""]


def _command_section(path: list[str], parser: argparse.ArgumentParser, level: int) -> list[str]:
    name = " ".join(path)
    lines = [f"{'#' * level} `{name}`", ""]
    if parser.description:
        lines += [_cell(parser.description), ""]
    usage = " ".join(parser.format_usage().split()).removeprefix("usage: ")
    lines += ["```text", usage, "```", ""]
    lines += _options_table(parser)
    for sub_name, sub in _subparsers(parser):
        lines += _command_section([*path, sub_name], sub, min(level + 1, 6))
    return lines


def command_parsers() -> dict[str, argparse.ArgumentParser]:
    """Every `beyond` subcommand's parser, as `beyond` itself builds it."""
    return dict(_subparsers(cli.build_parser()))


def cli_reference() -> str:
    """The command-line page: every subcommand, its subcommands and every option."""
    root = cli.build_parser()
    helps = {
        a.dest: a.help
        for act in root._actions
        if isinstance(act, argparse._SubParsersAction)
        for a in act._choices_actions
    }
    lines = [
        "# Command line",
        "",
        "Generated from the argparse parsers of `beyond` (`beyond_self/cli.py` and each",
        "command module's `add_arguments`) when the site is built; `beyond COMMAND --help`",
        "prints the same.",
        "",
        "| command | does |",
        "|---|---|",
    ]
    parsers = command_parsers()
    lines += [f"| [`{n}`](#beyond-{n}) | {_cell(helps.get(n) or '')} |" for n in parsers]
    lines.append("")
    for name, parser in parsers.items():
        section = _command_section(["beyond", name], parser, 2)
        section[0] = f"## `beyond {name}` {{#beyond-{name}}}"
        if helps.get(name):
            section[1:1] = ["", _cell(helps[name] or "") + "."]
        lines += section
    lines += [
        "## Environment variables {#environment}",
        "",
        "The bus options' defaults, read by every command and service",
        "(`runtime.bus.config.ENV_VARS`); an option given on the command line wins.",
        "",
        "| variable | meaning |",
        "|---|---|",
        *(f"| `{name}` | {_cell(text)} |" for name, text in config.ENV_VARS.items()),
        "",
    ]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------- messages


def _bounds(t: Any) -> str:
    parts = []
    for attr, sign in (("ge", "≥"), ("gt", ">"), ("le", "≤"), ("lt", "<")):
        value = getattr(t, attr, None)
        if value is not None:
            parts.append(f"{sign} {value}")
    for attr, sign in (("min_length", "length ≥"), ("max_length", "length ≤")):
        value = getattr(t, attr, None)
        if value is not None:
            parts.append(f"{sign} {value}")
    return f" ({', '.join(parts)})" if parts else ""


def type_text(t: Any) -> str:
    """A msgspec.inspect type as a short Python-like spelling, with its bounds."""
    i = msgspec.inspect
    if isinstance(t, i.Metadata):
        if t.extra_json_schema and "x-beyond-stamp" in t.extra_json_schema:
            return "stamp (ns since the epoch)"
        return type_text(t.type)
    if isinstance(t, i.StructType):
        return f"[`{t.cls.__name__}`](#{t.cls.__name__.lower()})"
    if isinstance(t, i.LiteralType):
        return " \\| ".join(f'`"{v}"`' if isinstance(v, str) else f"`{v}`" for v in t.values)
    if isinstance(t, i.UnionType):
        return " \\| ".join(type_text(x) for x in t.types)
    if isinstance(t, i.NoneType):
        return "None"
    if isinstance(t, i.DictType):
        return f"dict[{type_text(t.key_type)}, {type_text(t.value_type)}]{_bounds(t)}"
    if isinstance(t, i.ListType | i.VarTupleType | i.FrozenSetType | i.SetType):
        return f"list[{type_text(t.item_type)}]{_bounds(t)}"
    if isinstance(t, i.TupleType):
        return f"tuple[{', '.join(type_text(x) for x in t.item_types)}]"
    names: dict[type[Any], str] = {
        i.IntType: "int",
        i.FloatType: "float",
        i.StrType: "str",
        i.BoolType: "bool",
        i.BytesType: "bytes",
        i.AnyType: "any",
    }
    name: str = names.get(type(t), type(t).__name__)
    return name + _bounds(t)


def _structs(cls: type[Any], seen: dict[str, type[Any]]) -> None:
    """Every Struct a message holds, found through its fields."""
    info = msgspec.inspect.multi_type_info([cls])[0]
    stack = [info]
    while stack:
        t = stack.pop()
        if isinstance(t, msgspec.inspect.StructType):
            if t.cls.__name__ in seen:
                continue
            seen[t.cls.__name__] = t.cls
            stack.extend(f.type for f in t.fields)
        for attr in ("type", "item_type", "key_type", "value_type"):
            inner = getattr(t, attr, None)
            if inner is not None:
                stack.append(inner)
        for attr in ("types", "item_types"):
            stack.extend(getattr(t, attr, None) or ())


def _fields_table(cls: type[Any]) -> list[str]:
    info = msgspec.inspect.type_info(cls)
    assert isinstance(info, msgspec.inspect.StructType)
    rows = ["| field | type | default |", "|---|---|---|"]
    if info.tag_field:
        rows.append(f'| `{info.tag_field}` | `"{info.tag}"` (the type tag) | |')
    for f in info.fields:
        default = "" if f.required else f"`{f.default!r}`"
        if f.default is msgspec.NODEFAULT and not f.required:
            default = "(empty)"
        rows.append(f"| `{f.name}` | {type_text(f.type)} | {default} |")
    return [*rows, ""]


def message_types() -> list[type[Message]]:
    return [codec.REGISTRY[name] for name in sorted(codec.REGISTRY)]


def key_rows() -> list[tuple[str, str]]:
    """(key expression, what it carries) for every key of schemas/keys.py."""
    rows = [
        (f"beyond/<robot>/{suffix}", f"[`{cls.type_name()}`](#{cls.type_name().lower()})")
        for suffix, cls in keys.STREAMS.values()
    ]
    rows += [
        (f"beyond/<robot>/{key}", f"query: `{ask.type_name()}` in, `{reply.type_name()}` out")
        for key, (ask, reply) in keys.QUERIES.items()
    ]
    rows += [
        (f"beyond/<robot>/{chunk}/<service>", f"[`{cls.type_name()}`](#{cls.type_name().lower()})")
        for chunk, cls in keys.PER_SERVICE.items()
    ]
    rows.append((f"beyond/<robot>/{keys.ALIVE}/<service>", "liveliness token of a service"))
    return rows


def messages_reference() -> str:
    """The messages page: keys, then every message type with its fields, from `schemas/`."""
    lines = [
        "# Messages and keys",
        "",
        "Generated from `schemas/` (`schemas/keys.py`, `schemas/messages.py`) when the site is",
        "built. The JSON Schemas `beyond schemas export DIR` writes are served beside this page:",
        "[bus (msgpack) schemas](schemas/index.md) and their recording (JSON) forms.",
        "",
        "## Keys",
        "",
        "| key expression | carries |",
        "|---|---|",
        *(f"| `{k}` | {what} |" for k, what in key_rows()),
        "",
        "## Message types",
        "",
        "| type | version | wire encoding | keys |",
        "|---|---|---|---|",
    ]
    types = message_types()
    for cls in types:
        name = cls.type_name()
        found = schemas_cmd.keys_of(cls)
        queries = ", ".join(f"`{k}`" for k in schemas_cmd.queries_of(cls))
        where = ", ".join(f"`{k}`" for k in found) if found else f"(query/reply: {queries})"
        lines.append(
            f"| [`{name}`](#{name.lower()}) | {cls.VERSION} | "
            f"`{codec.wire_encoding(cls)}` | {where} |"
        )
    lines.append("")
    nested: dict[str, type[Any]] = {}
    for cls in types:
        name = cls.type_name()
        doc = " ".join((cls.__doc__ or "").split())
        lines += [f"### `{name}` {{#{name.lower()}}}", ""]
        if doc:
            lines += [_text(doc), ""]
        stamps = ", ".join(f"`{p}`" for p in codec.stamp_paths(cls))
        lines += [
            f"Version {cls.VERSION}, wire encoding `{codec.wire_encoding(cls)}`, "
            f"schema `{cls.schema_name()}`; stamps: {stamps or 'none'}.",
            "",
        ]
        lines += _fields_table(cls)
        _structs(cls, nested)
    lines += ["## Parts of messages", ""]
    for name in sorted(n for n in nested if n not in codec.REGISTRY):
        cls = nested[name]
        doc = " ".join((cls.__doc__ or "").split())
        lines += [f"### `{name}` {{#{name.lower()}}}", ""]
        if doc and not doc.startswith(f"{name}("):
            lines += [_text(doc), ""]
        lines += _fields_table(cls)
    return "\n".join(lines) + "\n"


def schema_files() -> dict[str, bytes]:
    """What `beyond schemas export` writes, by path relative to its folder."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        schemas_cmd.export(folder)
        return {
            str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()
        }


# ---------------------------------------------------------------------------- Python API


def api_modules(package: str) -> list[str]:
    """The public modules of `beyond_self.<package>`, in path order."""
    folder = ROOT / package
    names = []
    for path in sorted(folder.rglob("*.py")):
        parts = path.relative_to(folder).with_suffix("").parts
        if any(p.startswith("_") and p != "__init__" for p in parts):
            continue
        if parts[-1] == "__init__":
            parts = parts[:-1]
        names.append(".".join(["beyond_self", package, *parts]))
    return names


def api_page(package: str, title: str, intro: str) -> str:
    lines = [f"# {title}", "", intro, "", "Generated from the docstrings by mkdocstrings.", ""]
    for module in api_modules(package):
        lines += [f"::: {module}", "    options:", "      show_submodules: false", ""]
    return "\n".join(lines)


# ---------------------------------------------------------------------------- performance


class _Figures(string.Formatter):
    """str.format, plus two conversions for figures in seconds: `!m` (ms) and `!u` (µs)."""

    def convert_field(self, value: Any, conversion: str | None) -> Any:
        scale = {"m": 1e3, "u": 1e6}.get(conversion or "")
        if scale is not None:
            return float(value) * scale
        return super().convert_field(value, conversion)


_FORMATTER = _Figures()


def _fill(template: str, result: Mapping[str, Any]) -> str:
    """A row cell: a template whose fields name figures of the result, e.g. `{r[p99_ms]:.1f}`."""
    return _FORMATTER.format(template, r=result)


def _met(check: Mapping[str, Any], result: Mapping[str, Any]) -> str:
    value = float(_fill(check["value"], result))
    ok = ("min" not in check or value >= check["min"]) and (
        "max" not in check or value <= check["max"]
    )
    return "✓" if ok else "✗"


def results_files() -> list[Path]:
    return sorted((ROOT / "bench" / "results").glob("*.json"))


SIZING_CASES = (  # a limit's name, its rounds' name, what its robots do
    ("own", "fleet", "a person each (gestures at their own times)"),
    ("aligned", "fleet_aligned", "a burst (every robot's gestures end within one frame)"),
    ("camera", "fleet_camera", "a 15 fps camera each (object segmenter in the fleet)"),
)


def sizing_section(result: Mapping[str, Any]) -> list[str]:
    """How to size a workstation, from the fleet bench's limits: what one more robot costs in
    each case, so a reader can scale the measured machine to theirs."""
    limits = result.get("limits") or {}
    rows = []
    for case, rounds, what in SIZING_CASES:
        limit = limits.get(case)
        if not limit or not result.get(rounds):
            continue
        one = result[rounds][0]
        at_least = "at least " if limit.get("lower_bound") else ""
        per_core = 1 / limit["cores_per_added_robot"] if limit["cores_per_added_robot"] else 0
        rows.append(
            f"| {what} | {at_least}{limit['robots']} (p99 {limit['description_p99_ms']} ms) | "
            f"{limit['cores_per_added_robot']} | {per_core:.0f} | "
            f"{one['rss_mb']:.0f} MB | {limit['mb_per_added_robot']} MB | {limit['cpu_ratio']} |"
        )
    if not rows:
        return []
    return [
        "## Sizing a workstation",
        "",
        "From `bench/results/fleet.json` (its machine and provenance are in the table below):",
        "what one more robot costs the workstation's fleet processes (the gesture streamer, the",
        "reasoner, the describer, and the object segmenter with a camera), measured as the slope",
        "from one robot to the limit. Robots' own sources are not on a real workstation; the",
        "bench runs them on the same machine, so a real workstation has that CPU to spare.",
        "",
        "| robots | limit on the bench machine, description p99 < 33 ms | cores per added robot "
        "| robots per core (CPU) | memory at one robot | memory per added robot "
        "| CPU of one process set per robot, × |",
        "|---|---|---|---|---|---|---|",
        *rows,
        "",
        "To size a workstation: robots ≈ cores × 0.7 ÷ cores per added robot (a margin: the p99 "
        "grows fast as the cores fill up), and (memory − memory at one robot) ÷ memory per "
        "added robot; take the smaller. The steady cases are bound by CPU. A burst is bound "
        "by latency: a stage's robots are served one after another in its process, so give "
        "every core to each stage with `--shards auto` ([fleets](concepts/fleets.md)). Then "
        "measure on the machine itself: `.venv/bin/python bench/fleet.py --quick` searches "
        "each case's limit there.",
        "",
    ]


def performance_page() -> str:
    """The performance page: its notes (docs/performance.md), then tables made from the results
    files the bench scripts' JSON lines were kept in."""
    notes = (ROOT / "docs" / "performance.md").read_text(encoding="utf-8")
    lines = [
        notes.rstrip(),
        "",
        "## The figures",
        "",
        "Every figure below is read from `bench/results/*.json` when the site is built. Each file",
        "keeps the one line of JSON a `bench/` script printed (`result`), with the machine, the",
        "date and where the figures come from (`provenance`); a row's cells are templates over",
        "that line. Each script measures our code next to a reference in the same run, so the",
        "ratios are the figures to trust on a shared machine. Run one with",
        "`.venv/bin/python bench/NAME.py`; keep its last line in a results file to update this",
        "page.",
        "",
        "| script | measure | ours | reference, same run | ratio | goal |",
        "|---|---|---|---|---|---|",
    ]
    sources = []
    for path in results_files():
        data = json.loads(path.read_text(encoding="utf-8"))
        result = data["result"]
        for row in data["table"]:
            goal = row.get("goal", "")
            if "met" in row:
                goal = f"{goal} {_met(row['met'], result)}"
            cells = [_cell(_fill(row.get(c, ""), result)) for c in ("ours", "reference", "ratio")]
            measure = _cell(_fill(row["measure"], result))
            lines.append(
                f"| `{data['script']}` | {measure} | {' | '.join(cells)} | {_cell(goal)} |"
            )
        sources.append(
            f"| `{path.relative_to(ROOT)}` | {data['date']} | {_cell(data['machine'])} | "
            f"{_cell(data['provenance'])} |"
        )
    fleet = ROOT / "bench" / "results" / "fleet.json"
    if fleet.exists():
        lines += ["", *sizing_section(json.loads(fleet.read_text(encoding="utf-8"))["result"])]
    lines += [
        "",
        "## Where each figure comes from",
        "",
        "| results file | date | machine | provenance |",
        "|---|---|---|---|",
        *sources,
        "",
    ]
    return "\n".join(lines)


# ---------------------------------------------------------------------------- the science

FIGURES = ROOT / "docs" / "science" / "figures"


def _sentences(items: list[list[Any]]) -> list[str]:
    rows = ["| # | sentence | score |", "|---:|---|---:|"]
    rows += [f"| {n} | {text} | {score:.5f} |" for n, (text, score) in enumerate(items, 1)]
    return [*rows, ""]


def reproduce_tables() -> str:
    """Tables of the committed `beyond reproduce` results, appended to science/reproduce.md."""
    from beyond_self.cognition.reproduction import figures_table

    r = json.loads((FIGURES / "results.json").read_text(encoding="utf-8"))
    lines = ["", *figures_table(r["published"])]
    lines += ["", "## The N-best lists of experiment 5", ""]
    for key, title in (
        ("exp5_gesture", "Yellow big fast sphere, action from the recorded gesture"),
        ("exp5_and", "Action=grasp, ObjVel=medium"),
        ("exp5_but", "Action=grasp, ObjVel=slow"),
    ):
        lines += [f"### {title}", "", "The article's sampled list, re-scored:", ""]
        lines += _sentences(r[key])
        lines += ["Exact search over the whole grammar:", ""]
        lines += _sentences(r[f"{key}_exact"])
    lines += [
        "## The object words of experiment 6",
        "",
        "| action, object | sentence |",
        "|---|---|",
    ]
    lines += [f"| {what} | {text} |" for what, text in r["exp6"].items()]
    return "\n".join([*lines, ""])


# ---------------------------------------------------------------------------- the build


def pages() -> dict[str, str | bytes]:
    """Every generated file, by its path under docs/."""
    out: dict[str, str | bytes] = {
        "reference/cli.md": cli_reference(),
        "reference/messages.md": messages_reference(),
        "reference/api-runtime.md": api_page(
            "runtime",
            "Python API: beyond_self.runtime",
            "The bus every service stands on: session and configuration, typed publish and "
            "subscribe, the `Service` base, recording and replay. Start with "
            "[the tutorial](../tutorial.md#5-write-your-own-service).",
        ),
        "reference/api-cognition.md": api_page(
            "cognition",
            "Python API: beyond_self.cognition",
            "The science as a plain library, no bus: the network, gestures, fusion, "
            "descriptions, vision, the per-gesture episodes. See "
            "[the science](../science/index.md).",
        ),
        "performance.md": performance_page(),
    }
    reproduce = ROOT / "docs" / "science" / "reproduce.md"
    out["science/reproduce.md"] = reproduce.read_text(encoding="utf-8") + reproduce_tables()
    files = schema_files()
    index = files.pop("README.md").decode()
    out["reference/schemas/index.md"] = index
    for name, data in files.items():
        out[f"reference/schemas/{name}"] = data
    return out


if __name__ == "<run_path>":  # run by mkdocs-gen-files
    import mkdocs_gen_files

    for name, content in pages().items():
        mode = "wb" if isinstance(content, bytes) else "w"
        with mkdocs_gen_files.open(name, mode) as handle:
            handle.write(content)
