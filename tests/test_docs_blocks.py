"""Every shell and Python block of the README and the docs runs as a reader types it, or says why
not.

A reader's shell: the environment of a fresh login (no .venv on PATH, no variable of ours, a
home of its own) that ran the README's set-up block (`<!-- set-up: ... -->`, activating .venv),
in a fresh copy of the clone (its tracked files, with the .venv `make` made), a new shell for
each block. A block starts from a fresh copy unless marked `<!-- needs: WHAT -->`: then it runs
after the blocks before it, in their copy. `<!-- not run: REASON -->` skips a block;
`<!-- file: NAME -->` writes it to NAME. A `text` block right after a block that runs is its
output: each of its lines must be printed, in that order. What a block leaves running is
stopped when it ends. The one variable a reader lacks is the bus port of the test's own.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from busutil_net import free_port

REPO = Path(__file__).resolve().parent.parent
PAGES = [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]
RUNNABLE = {"sh", "bash", "python"}
FENCE = re.compile(r"^(\s*)```(\S*)\s*$")
MARKER = re.compile(r"^\s*<!--\s*(not run|file|needs|set-up):\s*(.*?)\s*-->\s*$")
BLOCK_TIMEOUT_S = 150


@dataclass
class Block:
    lang: str
    code: str
    line: int
    marker: str = ""  # "", "not run", "file", "needs" or "set-up"
    argument: str = ""  # the reason, the file's name, or what it needs
    output: str | None = None  # the text block that follows, if any


def blocks(text: str) -> list[Block]:
    """The fenced blocks of a Markdown page, with their markers and expected outputs."""
    lines = text.splitlines()
    found: list[Block] = []
    previous = ""  # the last non-blank line before the current one
    last_closed: Block | None = None  # a block whose fence closed on the last non-blank line
    i = 0
    while i < len(lines):
        opening = FENCE.match(lines[i])
        if not opening:
            if lines[i].strip():
                previous, last_closed = lines[i], None
            i += 1
            continue
        indent, lang, start = opening.group(1), opening.group(2), i
        body = []
        i += 1
        while i < len(lines) and lines[i].strip() != "```":
            body.append(lines[i].removeprefix(indent))
            i += 1
        code = "\n".join(body) + "\n"
        marker = MARKER.match(previous)
        if lang == "text" and last_closed is not None and last_closed.output is None:
            last_closed.output = code
            block = None
        else:
            block = Block(lang, code, start + 1)
            if marker:
                block.marker, block.argument = marker.group(1), marker.group(2)
            found.append(block)
        previous, last_closed = lines[i] if i < len(lines) else "", block
        i += 1
    return found


def page_id(page: Path) -> str:
    return str(page.relative_to(REPO))


def test_readme_is_at_most_150_lines() -> None:
    assert len((REPO / "README.md").read_text(encoding="utf-8").splitlines()) <= 150


@pytest.mark.parametrize("page", PAGES, ids=page_id)
def test_every_block_says_its_language_and_every_skip_its_reason(page: Path) -> None:
    for block in blocks(page.read_text(encoding="utf-8")):
        where = f"{page_id(page)}:{block.line}"
        assert block.lang, f"{where}: a fenced block without a language"
        if block.marker:
            assert block.argument, f"{where}: <!-- {block.marker}: ... --> needs its reason or name"
            assert block.lang in RUNNABLE, f"{where}: a marker on a {block.lang} block"


def test_the_tutorial_service_is_the_runtime_readme_example() -> None:
    readme = (REPO / "runtime" / "README.md").read_text(encoding="utf-8")
    example = re.search(r"<!-- example-service -->\n```python\n(.*?)```", readme, re.S)
    assert example is not None
    tutorial = blocks((REPO / "docs" / "tutorial.md").read_text(encoding="utf-8"))
    timer = [b for b in tutorial if b.marker == "file" and b.argument == "timer.py"]
    assert [b.code for b in timer] == [example.group(1)]


def test_the_tutorial_shows_the_demo_lines_the_readme_promises() -> None:
    """tests/test_package.py and tests/test_pipeline_up.py check the README's lines against real
    runs; the tutorial's demo block (not run here: the same run, 20 s) must show the same."""
    readme = blocks((REPO / "README.md").read_text(encoding="utf-8"))
    tutorial = blocks((REPO / "docs" / "tutorial.md").read_text(encoding="utf-8"))
    (promised,) = [b.code for b in readme if b.lang == "text" and "\ngesture 2: " in b.code]
    (demo,) = [b for b in tutorial if b.code == "beyond demo --no-live\n"]
    shown = (demo.output or "").splitlines()
    assert [line for line in shown if line.startswith("gesture ")] == [
        line for line in promised.splitlines() if line.startswith("gesture ")
    ]
    assert len(shown) > 14


def test_the_block_reader_finds_markers_outputs_and_indented_blocks() -> None:
    page = (
        "<!-- not run: needs a robot -->\n```sh\nbeyond up\n```\n\n"
        "1. a step\n\n    ```sh\n    echo hi\n    ```\n\n    ```text\n    hi\n    ```\n\n"
        "<!-- file: a.py -->\n```python\nprint(1)\n```\n\nprose\n\n```text\nnot an output\n```\n"
        "<!-- needs: a.py -->\n```sh\npython a.py\n```\n"
    )
    got = blocks(page)
    assert [(b.lang, b.marker, b.argument, b.output) for b in got] == [
        ("sh", "not run", "needs a robot", None),
        ("sh", "", "", "hi\n"),
        ("python", "file", "a.py", None),
        ("text", "", "", None),
        ("sh", "needs", "a.py", None),
    ]
    assert got[1].code == "echo hi\n"


def set_up() -> str:
    """The README's set-up blocks: what a reader's shell ran before any block of the docs."""
    readme = blocks((REPO / "README.md").read_text(encoding="utf-8"))
    return "".join(b.code for b in readme if b.marker == "set-up")


def _reader_path() -> str:
    """The machine's PATH without the test's virtual environment or anything in the checkout."""
    ours = (Path(sys.prefix).resolve(), REPO)
    kept = [
        entry
        for entry in os.environ.get("PATH", os.defpath).split(os.pathsep)
        if entry and not any(Path(entry).resolve().is_relative_to(root) for root in ours)
    ]
    return os.pathsep.join(kept)


def _environment(home: Path) -> dict[str, str]:
    """A fresh login's environment; the bus port is the test's own (tests run side by side)."""
    env = {"PATH": _reader_path(), "HOME": str(home), "SHELL": "/bin/bash"}
    for name in ("LANG", "LC_ALL", "USER", "LOGNAME", "TZ"):
        if name in os.environ:
            env[name] = os.environ[name]
    env["BEYOND_ZENOH_PORT"] = str(free_port())
    return env


def _clone(folder: Path) -> Path:
    """A fresh copy of the clone after its set-up: the checkout's files git knows of (tracked,
    or new and not ignored), and `.venv`, the environment these tests run in."""
    venv = Path(sys.prefix)
    if not (venv / "bin" / "activate").is_file():
        pytest.skip(f"the tests run in {venv}, not a virtual environment with bin/activate")
    if shutil.which("git") is None or not (REPO / ".git").exists():
        pytest.skip("git or the checkout's .git is absent: the clone's files are not known")
    listed = subprocess.run(
        ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
        cwd=REPO,
        capture_output=True,
        check=True,
    ).stdout.decode()
    for rel in filter(None, listed.split("\0")):
        src, dst = REPO / rel, folder / rel
        if not src.is_symlink() and not src.is_file():
            continue  # deleted in the working tree, or a submodule
        dst.parent.mkdir(parents=True, exist_ok=True)
        if src.is_symlink():
            dst.symlink_to(os.readlink(src))
        else:
            shutil.copy2(src, dst)
    (folder / ".venv").symlink_to(venv, target_is_directory=True)
    return folder


def _run(
    block: Block, folder: Path, env: dict[str, str], n: int
) -> subprocess.CompletedProcess[str]:
    code = block.code
    if block.lang == "python":
        script = folder / f"_block_{n}.py"
        script.write_text(block.code, encoding="utf-8")
        code = f"python {script.name}\n"
    command = ["bash", "-euo", "pipefail", "-c", set_up() + code]
    proc = subprocess.Popen(
        command,
        cwd=folder,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own group: what it leaves running is stopped below
    )
    try:
        out, err = proc.communicate(timeout=BLOCK_TIMEOUT_S)
    finally:
        for sig in (signal.SIGTERM, signal.SIGKILL):
            try:
                os.killpg(proc.pid, sig)
            except ProcessLookupError:
                break
        proc.wait()
    return subprocess.CompletedProcess(command, proc.returncode, out, err)


def test_a_readers_shell_has_no_beyond_until_it_runs_the_set_up(tmp_path: Path) -> None:
    """The shell the blocks run in finds `beyond` only through the README's set-up."""
    folder = _clone(tmp_path / "clone")
    env = _environment(tmp_path / "home")
    bare = subprocess.run(
        ["bash", "-c", "command -v beyond python || true"],
        cwd=folder,
        env=env,
        capture_output=True,
        text=True,
        check=True,
        timeout=30,
    )
    assert not any(line.startswith(sys.prefix) for line in bare.stdout.splitlines()), bare.stdout
    assert set_up(), "README.md has no <!-- set-up: ... --> block"
    found = _run(Block("sh", "command -v beyond\nbeyond --version\n", 0), folder, env, 0)
    assert found.returncode == 0, found.stderr
    where = Path(found.stdout.splitlines()[0]).parent.resolve()
    assert where == (folder / ".venv" / "bin").resolve(), found.stdout  # .venv's own beyond


def test_the_tutorial_sets_up_the_shell_as_the_readme_does() -> None:
    tutorial = blocks((REPO / "docs" / "tutorial.md").read_text(encoding="utf-8"))
    install = next(b for b in tutorial if "make demo" in b.code)
    assert set_up() and set_up() in install.code


def _printed_in_order(expected: str, printed: str) -> str | None:
    """The first expected line not printed after the previous one, or None."""
    got = [line.rstrip() for line in printed.splitlines()]
    at = 0
    for line in (x.rstrip() for x in expected.splitlines() if x.strip()):
        try:
            at = got.index(line, at) + 1
        except ValueError:
            return line
    return None


def test_an_output_is_checked_line_by_line_in_order() -> None:
    printed = "pipeline up\ngesture 1: a\nlog line\ngesture 2: b\n"
    assert _printed_in_order("gesture 1: a\ngesture 2: b\n", printed) is None
    assert _printed_in_order("gesture 2: b\ngesture 1: a\n", printed) == "gesture 1: a"
    assert _printed_in_order("gesture 3: c\n", printed) == "gesture 3: c"


RUN_PAGES = [
    p
    for p in PAGES
    if any(not b.marker and b.lang in RUNNABLE for b in blocks(p.read_text(encoding="utf-8")))
]


@pytest.mark.slow
@pytest.mark.parametrize("page", RUN_PAGES, ids=page_id)
def test_the_blocks_run_as_written(page: Path, tmp_path: Path) -> None:
    env = _environment(tmp_path / "home")
    folder: Path | None = None
    ran = 0
    for n, block in enumerate(blocks(page.read_text(encoding="utf-8"))):
        if block.lang not in RUNNABLE or block.marker in ("not run", "set-up"):
            continue
        where = f"{page_id(page)}:{block.line}"
        if block.marker != "needs":
            folder = _clone(tmp_path / f"clone-{n}")
        assert folder is not None, f"{where}: needs {block.argument}, but no block ran before it"
        if block.marker == "file":
            (folder / block.argument).write_text(block.code, encoding="utf-8")
            continue
        result = _run(block, folder, env, n)
        assert result.returncode == 0, (
            f"{where} exited {result.returncode}\n{block.code}\nstdout:\n{result.stdout[-2000:]}"
            f"\nstderr:\n{result.stderr[-3000:]}"
        )
        if block.output is not None:
            missing = _printed_in_order(block.output, result.stdout)
            assert missing is None, (
                f"{where} did not print {missing!r}; it printed:\n{result.stdout}"
            )
        ran += 1
    assert ran > 0
