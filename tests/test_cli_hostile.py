"""Hostile command lines: every `beyond` subcommand either works or exits 2 with its error on the
first line of stderr; never a traceback, never a hang.

Two parts. The corpus of issue 16 (each case found by hand once) is a regression test, case by
case. The property test then searches for counter-examples: for every subcommand (found by
walking the real parser, so a new option is fuzzed without touching this file) it generates
command lines where at least one argument is bad (a non-finite or out-of-range number, an
unwritable output, an invalid key expression, a value outside the choices, an unknown option, a
missing required argument, or a damaged/garbage/empty/binary input file) and the others are
drawn from good and bad values alike. Every case runs in a fork of one warm worker process
(tests/cli_fuzz_worker.py) under a timeout. Failures are collected, not raised one by one, so a
run reports every counter-example it found, in bounded time.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import random
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from busutil_net import REPO, env_for, free_port, private_config
from hypothesis import HealthCheck, Phase, given, seed, settings
from hypothesis import strategies as st

from beyond_self.cli import build_parser
from beyond_self.commands import argtypes
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.recording.reader import inspect_recording
from beyond_self.services.launcher import BEYOND

CASE_TIMEOUT = 60.0  # a hang, on a loaded 2-core machine (cases take well under a second)
TOTAL_CASES = 2000  # spread over the subcommands; the issue asks for at least 2,000
BUS_OPTIONS = {"--robot", "--mode", "--connect", "--listen", "--zenoh-config", "--port"}
# these run until stopped when their arguments are good: only bad-at-parse cases for them
FOREVER = {("router",), ("service",), ("up",), ("demo",)}


@dataclass
class Result:
    rc: int | None
    hung: bool
    stdout: str
    stderr: str

    def problem(self, codes: tuple[int, ...] = (0, 2)) -> str | None:
        """What is wrong with this outcome, or None when it keeps the promise."""
        if self.hung:
            return "hung"
        if "Traceback (most recent call last)" in self.stderr:
            return "traceback: " + self.stderr.strip().splitlines()[-1][:300]
        if self.rc not in codes:
            return f"exit {self.rc}: {self.stderr[-300:]!r}"
        if self.rc == 2:
            first = self.stderr.strip().splitlines()[0] if self.stderr.strip() else ""
            if "error" not in first.lower():
                return f"exit 2 but the first stderr line is no error: {self.stderr[:300]!r}"
        return None


class Worker:
    def __init__(self, cwd: Path, env: dict[str, str]) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, str(REPO / "tests" / "cli_fuzz_worker.py")],
            cwd=cwd,
            env=env,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.proc.stdout is not None
        assert json.loads(self.proc.stdout.readline()) == {"ready": True}
        self.cases = 0

    def run(self, argv: list[str], timeout: float = CASE_TIMEOUT) -> Result:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(json.dumps({"argv": argv, "timeout": timeout}) + "\n")
        self.proc.stdin.flush()
        self.cases += 1
        return Result(**json.loads(self.proc.stdout.readline()))

    def close(self) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.close()
        self.proc.wait(30)


@pytest.fixture(scope="module")
def arena(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder of hostile files, the cwd of every case (names below are relative to it)."""
    root = tmp_path_factory.mktemp("hostile")
    rng = random.Random(16)
    (root / "garbage.bin").write_bytes(bytes(rng.randrange(256) for _ in range(5000)))
    (root / "empty.txt").write_bytes(b"")
    (root / "binary.yaml").write_bytes(b"\xff\xfe\x00\x01binary\x80\x81")
    (root / "junk.json").write_text('{"services": 5, "nodes": [1, 2', encoding="utf-8")
    (root / "list.json").write_text("[1, 2, 3]", encoding="utf-8")
    (root / "deep.json").write_text("[" * 50_000, encoding="utf-8")
    (root / "text.txt").write_text("grasp the ball\nthe robot taps\n\x07", encoding="utf-8")
    shipped = (REPO / "recordings" / "touch-box.mcap").read_bytes()
    (root / "half.mcap").write_bytes(shipped[:200_000])  # a recording killed half-way
    (root / "head.mcap").write_bytes(shipped[:40])  # magic and a cut header
    # magic, then a record claiming to be 2^40 bytes long (a reader must not try to allocate it)
    (root / "huge.mcap").write_bytes(shipped[:8] + b"\x06" + (2**40).to_bytes(8, "little"))
    (root / "adir").mkdir()
    return root


@pytest.fixture(scope="module")
def model(arena: Path) -> Path:
    from beyond_self.cli import main

    path = arena / "model.json"
    assert main(["bn", "learn", "-o", str(path)]) == 0
    return path


@pytest.fixture(scope="module")
def worker(arena: Path) -> Iterator[Worker]:
    env = dict(os.environ)
    for name in ("BEYOND_ZENOH_CONFIG", "BEYOND_ZENOH_CONNECT", "BEYOND_ZENOH_LISTEN"):
        env.pop(name, None)
    env.update(
        BEYOND_ZENOH_PORT=str(free_port()),
        BEYOND_ROBOT="hostile",
        PYTHONPATH=str(REPO),
        MPLBACKEND="Agg",
        COLUMNS="120",
    )
    w = Worker(arena, env)
    yield w
    w.close()


# ---------------------------------------------------------------- the corpus of issue 16

SHIPPED = str(REPO / "recordings" / "touch-box.mcap")
CORPUS: list[tuple[str, list[str], str]] = [
    # (name, argv, what the one error line must say); MODEL is replaced by a learnt model
    ("bn learn -o unwritable", ["bn", "learn", "-o", "garbage.bin/m.json"], "not a folder"),
    ("simulate -o unwritable", ["simulate", "touch-box", "-o", "garbage.bin/x.mcap"], "folder"),
    ("record -o unwritable", ["record", "-o", "garbage.bin/x.mcap", "--duration", "1"], "folder"),
    ("describe --plot unwritable", ["describe", "MODEL", "--plot", "adir"], "is a folder"),
    (
        "gesture stream --plot unwritable",
        ["gesture", "stream", "m.json", "x.log", "--plot", "no/such/p.png"],
        "does not exist",
    ),
    ("segment --overlay unwritable", ["segment", SHIPPED, "--overlay", "adir"], "is a folder"),
    ("segment --evaluate unwritable", ["segment", "--evaluate", "garbage.bin"], "not a folder"),
    ("service --config binary", ["service", "reasoner", "--config", "binary.yaml"], "UTF-8"),
    ("up --config binary", ["up", "--config", "binary.yaml", "--no-live"], "UTF-8"),
    ("up --timeout -1", ["up", "--timeout", "-1", "--no-live"], "out of range"),
    ("up --timeout nan", ["up", "--timeout", "nan", "--no-live"], "out of range"),
    ("echo bad key", ["echo", "a//b", "--duration", "1"], "invalid key expression"),
    ("record bad key", ["record", "a//b", "-o", "r.mcap"], "invalid key expression"),
    ("replay --topics bad key", ["replay", SHIPPED, "--topics", "a//b"], "invalid key"),
    ("ask --timeout -1", ["ask", "--query", "Action", "--timeout", "-1"], "out of range"),
    (
        "replay --wait-for times out",
        ["replay", SHIPPED, "--wait-for", "beyond/hostile/alive/nobody", "--wait-timeout", "0.5"],
        "nothing alive matched --wait-for",
    ),
    ("echo --duration nan", ["echo", "beyond/**", "--duration", "nan"], "out of range"),
    ("record --duration nan", ["record", "-o", "r.mcap", "--duration", "nan"], "out of range"),
    ("replay garbage", ["replay", "garbage.bin"], "not an MCAP recording"),
    ("replay a folder", ["replay", "adir"], "is a folder"),
    ("replay a cut header", ["replay", "head.mcap"], "nothing readable"),
    ("replay a huge record", ["replay", "huge.mcap"], "past any limit"),
    ("inspect a huge record", ["inspect", "huge.mcap"], "past any limit"),
    ("segment killed recording", ["segment", "half.mcap"], "played the other HALF"),
    ("describe empty sentences", ["describe", "MODEL", "--sentences", "empty.txt"], "is empty"),
    ("describe --nbest 1e12", ["describe", "MODEL", "--nbest", "1000000000000"], "[1, 10000]"),
    ("describe --samples 1e12", ["describe", "MODEL", "--samples", "10**12"], "integer"),
    (
        "service --set of the wrong type",
        ["service", "reasoner", "--set", 'deadline_s="abc"'],
        "must be float",
    ),
    ("service --set nan", ["service", "reasoner", "--set", "deadline_s=NaN"], "finite"),
    ("service --set negative", ["service", "objects", "--set", "onset_s=-1"], ">= 0"),
    ("--port out of range", ["topics", "--port", "70000"], "TCP port"),
    ("--zenoh-config garbage", ["topics", "--zenoh-config", "garbage.bin"], "Zenoh config"),
]


@pytest.mark.parametrize(("argv", "says"), [c[1:] for c in CORPUS], ids=[c[0] for c in CORPUS])
def test_issue_corpus(worker: Worker, model: Path, arena: Path, argv: list[str], says: str) -> None:
    says = says.replace("HALF", str(_readable(arena / "half.mcap")))
    result = worker.run([str(model) if a == "MODEL" else a for a in argv])
    assert result.problem() is None, result.problem()
    assert result.rc == 2, result
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, f"not one line: {result.stderr!r}"
    assert says in lines[0], lines[0]


def _readable(path: Path) -> int:
    """Messages `beyond inspect` finds readable in a damaged recording (more than none)."""
    info = inspect_recording(path)
    assert info.error and info.messages > 0
    return info.messages


def test_replay_of_a_killed_recording_says_what_it_replayed(worker: Worker, arena: Path) -> None:
    """It reported 'readable: 0 messages' and then replayed 79. Now: it replays what is
    readable, says what was lost in the one line every command says, and exits 2 (issue 21)."""
    n = _readable(arena / "half.mcap")
    result = worker.run(["replay", "half.mcap", "--afap"])
    assert result.rc == 2, result
    assert f"replayed {n} messages" in result.stderr
    (error,) = [line for line in result.stderr.splitlines() if "error" in line]
    assert "half.mcap is damaged: truncated" in error and f"played the other {n}" in error


async def test_replay_honours_beyond_robot(arena: Path) -> None:
    """BEYOND_ROBOT renames the recording's keys, as recordings/README.md says (it was ignored:
    only --robot renamed). The replay waits for our token, so discovery cannot lose messages."""
    config = private_config()
    with Bus.open(config) as bus:
        sub = bus.subscribe_raw(f"beyond/{config.robot}/**")
        bus.declare_token(bus.keys.alive("hostile-test"))
        proc = await asyncio.create_subprocess_exec(
            *BEYOND, "replay", SHIPPED, "--afap",
            "--wait-for", bus.keys.alive("hostile-test"),
            cwd=arena, env=env_for(config), stderr=asyncio.subprocess.PIPE,
        )  # fmt: skip
        _, err = await asyncio.wait_for(proc.communicate(), 120)
        assert proc.returncode == 0, err
        received = ticks = 0
        while True:
            try:
                sample = await sub.recv(2.0)
            except TimeoutError:
                break
            assert sample.key.startswith(f"beyond/{config.robot}/")
            if sample.key == bus.keys.clock:  # the replay's stream clock, for the renamed robot
                ticks += 1
            else:
                received += 1
    assert f"replayed {received} messages" in err.decode(), (received, err)
    assert ticks > 0


# ---------------------------------------------------------------- the property test


@dataclass
class Slot:
    """One argument of a subcommand: its option string (None: positional) and its kind."""

    option: str | None
    kind: str  # number, output_file, output_dir, key, choice, flag, file, text
    action: argparse.Action

    @property
    def forcible(self) -> bool:
        """Has values that are surely bad (a forced bad slot must make the case fail)."""
        return self.kind in {"number", "output_file", "output_dir", "key", "choice", "file"}


def _kind(action: argparse.Action) -> str:
    t = action.type
    if action.nargs == 0:
        return "flag"
    if action.choices:
        return "choice"
    if t is argtypes.keyexpr:
        return "key"
    if t is argtypes.output_file:
        return "output_file"
    if t is argtypes.output_dir:
        return "output_dir"
    if t in (int, float) or getattr(t, "__qualname__", "").startswith("number."):
        return "number"
    if t is Path or action.dest in {"file", "model", "models", "log", "zenoh_config", "config"}:
        return "file"
    return "text"


def _commands() -> list[tuple[tuple[str, ...], list[Slot]]]:
    def walk(parser: argparse.ArgumentParser, path: tuple[str, ...]) -> Iterator[Any]:
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if subs:
            for name, sub in subs[0].choices.items():
                yield from walk(sub, (*path, name))
            return
        slots = [
            Slot(a.option_strings[0] if a.option_strings else None, _kind(a), a)
            for a in parser._actions
            if not isinstance(a, argparse._HelpAction)
        ]
        yield path, slots

    return list(walk(build_parser(), ()))


COMMANDS = _commands()
PER_COMMAND = -(-TOTAL_CASES // len(COMMANDS))

BAD = {
    "number": ["nan", "NaN", "inf", "-inf", "-1", "-0.5", "1e400", "1e300", "abc", "", "0x1f",
               "99999999999999999999999", "1e19", "--", "-9223372036854775809", "1,5"],
    "output_file": ["garbage.bin/x.out", "adir", "no/such/dir/x.out", "", " "],
    "output_dir": ["garbage.bin/sub", "garbage.bin", "", "x" * 300],
    "key": ["a//b", "", "/", "a/", "a/**/**", "a?b", "a#b", "*x", "beyond/*a", "/beyond/**"],
    "file": ["nope.mcap", "adir", "garbage.bin", "empty.txt", "binary.yaml", "half.mcap",
             "head.mcap", "huge.mcap", "deep.json", "junk.json", "list.json", "garbage.bin/x",
             "x" * 300],
}  # fmt: skip
GOOD = {
    "number": ["1", "2", "0.5"],
    "output_file": ["out.x"],
    "output_dir": ["outdir"],
    "key": ["beyond/hostile/**"],
    "file": ["text.txt", "MODEL", SHIPPED],
    "text": ["Action=grasp", "Action", "grasp=0.5,tap=0.5", "1:20", "robot", "cv", "synthetic"],
}
TEXT = st.text(
    st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"), max_size=30
)


def _value(draw: Any, slot: Slot, bad: bool) -> str:
    if slot.kind == "choice":
        choices = [str(c) for c in slot.action.choices or ()]
        if bad:
            return draw(TEXT.filter(lambda t: t not in choices and not t.startswith("-")))
        return draw(st.sampled_from(choices))
    if slot.kind == "text":
        pool = GOOD["text"] + BAD["file"]
        return draw(st.one_of(st.sampled_from(pool), TEXT))
    if bad:
        pool = BAD[slot.kind]
        if slot.kind == "number":
            extra = st.one_of(
                st.floats(allow_nan=True, allow_infinity=True).filter(lambda x: not x >= 0),
                st.integers(min_value=2**63),
            ).map(repr)
            return draw(st.one_of(st.sampled_from(pool), extra))
        return draw(st.sampled_from(pool))
    return draw(st.sampled_from(GOOD[slot.kind] + BAD[slot.kind]))


def _case(draw: Any, path: tuple[str, ...], slots: list[Slot]) -> list[str]:
    usable = [s for s in slots if s.kind != "flag" or s.option is not None]
    forcible = [s for s in usable if s.forcible]
    if path in FOREVER:  # good files would start them: only what the parser refuses
        forcible = [s for s in forcible if s.kind not in {"file"}]
    required = [s for s in usable if s.option and s.action.required]
    special = ["unknown option"] + (["missing required"] if required else [])
    forced = draw(st.sampled_from(special + [s.option or s.action.dest for s in forcible]))
    positional: list[str] = []
    options: list[list[str]] = []
    for slot in usable:
        name = slot.option or slot.action.dest
        is_forced = name == forced
        if slot.option is None:
            nargs = slot.action.nargs
            if nargs in ("?", "*") and not is_forced and draw(st.booleans()):
                continue
            positional.append(_value(draw, slot, is_forced))
            continue
        wanted = is_forced or (slot.action.required and forced != "missing required")
        if not wanted and draw(st.integers(0, 3)) != 0:
            continue
        if forced == "missing required" and slot is required[0]:
            continue
        if slot.kind == "flag":
            options.append([slot.option])
            continue
        n = slot.action.nargs if isinstance(slot.action.nargs, int) else 1
        options.append([slot.option, *(_value(draw, slot, is_forced) for _ in range(n))])
    if forced == "unknown option":
        options.append([draw(st.sampled_from(["--no-such-option", "--nbest-x", "-Z"]))])
    options = draw(st.permutations(options))
    tail = [token for group in options for token in group]
    return [*path, *positional, *tail]


@pytest.mark.slow
@pytest.mark.parametrize(("path", "slots"), COMMANDS, ids=[" ".join(p) for p, _ in COMMANDS])
def test_no_command_line_crashes_or_hangs(
    worker: Worker, model: Path, path: tuple[str, ...], slots: list[Slot]
) -> None:
    failures: list[str] = []
    ran = 0

    @seed(16)
    @settings(
        max_examples=PER_COMMAND,
        deadline=None,
        database=None,
        phases=[Phase.generate],  # every counter-example is collected below; no shrinking
        suppress_health_check=list(HealthCheck),
    )
    @given(st.data())
    def check(data: st.DataObject) -> None:
        nonlocal ran
        argv = [str(model) if a == "MODEL" else a for a in data.draw(_case_strategy(path, slots))]
        ran += 1
        result = worker.run(argv)
        # `beyond health` answers "unhealthy" with 1, as a container HEALTHCHECK requires
        problem = result.problem((0, 1, 2) if path[0] == "health" else (0, 2))
        if problem is not None:
            failures.append(f"{argv!r}: {problem}")

    check()
    print(f"{' '.join(path)}: {ran} generated cases, {len(failures)} failed")
    # hypothesis stops early only on a tiny space (a command with one option or none)
    assert ran >= (PER_COMMAND // 2 if len(slots) > 1 else 1)
    assert not failures, "\n".join(failures[:20])


def _case_strategy(path: tuple[str, ...], slots: list[Slot]) -> st.SearchStrategy[list[str]]:
    @st.composite
    def build(draw: Any) -> list[str]:
        return _case(draw, path, slots)

    return build()
