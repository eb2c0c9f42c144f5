"""Argument types every command shares, so a bad value is refused while parsing, before any work.

Why here and not in each command: `type=float` accepts `nan`, `inf` and `1e308`, `type=int`
accepts `10**100`, and a path is only found unwritable after minutes of work (or never, for a
command that writes at the very end). One checked type per kind of value, with the valid range
in its message, makes every command refuse the same things the same way (exit 2, one line).
"""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from beyond_self.core.errors import InputError
from beyond_self.runtime.recording.replay_control import RATE_MAX
from beyond_self.runtime.shard import shard_count

SEED_MAX = 2**32 - 1  # numpy's legacy seeding and our simulators take 32-bit seeds
SECONDS_MAX = 366 * 86400.0  # a year: longer is a typo, and asyncio deadlines stay exact


def _fmt(value: float) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def number(
    kind: type[int] | type[float],
    *,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    what: str = "",
) -> Callable[[str], float]:
    """An argparse type: a finite `kind` in [lo, hi] (or (lo, hi] with `lo_open`)."""
    if lo is not None and hi is not None:
        valid = f"{'(' if lo_open else '['}{_fmt(lo)}, {_fmt(hi)}]"
    elif lo is not None:
        valid = f"{'>' if lo_open else '>='} {_fmt(lo)}"
    else:
        valid = "any"
    noun = "an integer" if kind is int else "a finite number"
    expected = f"{noun} {valid}" + (f" ({what})" if what else "")

    def parse(text: str) -> float:
        try:
            value: float = kind(text)
        except (ValueError, OverflowError):
            raise argparse.ArgumentTypeError(f"{text!r} is not {expected}") from None
        if (
            not math.isfinite(value)
            or (lo is not None and (value <= lo if lo_open else value < lo))
            or (hi is not None and value > hi)
        ):
            raise argparse.ArgumentTypeError(f"{text!r} out of range; valid: {expected}")
        return value

    parse.__name__ = kind.__name__  # argparse names the type in some messages
    parse.what = what  # type: ignore[attr-defined]  # what the number is (tests/test_cli_flags.py)
    return parse


def seconds(*, zero: bool = False) -> Callable[[str], float]:
    """A duration or timeout in seconds: finite, positive (or >= 0 with `zero`), at most a year."""
    return number(float, lo=0.0, hi=SECONDS_MAX, lo_open=not zero, what="seconds")


def count(lo: int = 1, hi: int = 2**62, what: str = "") -> Callable[[str], float]:
    return number(int, lo=lo, hi=hi, what=what)


seed = number(int, lo=0, hi=SEED_MAX, what="seed")
# a replay's speed as typed: 0 means as fast as possible
# (runtime.recording.replay_control.rate_option
# turns it into the engine's None), so every command takes the same values
rate = number(float, lo=0, hi=RATE_MAX, what="speed factor, 0: as fast as possible")


NOTES = "_notes"  # attribute of the parsed arguments: notes printed once the command has run


def note(args: argparse.Namespace, text: str) -> None:
    """Say `text` once the command has run (on stderr, after its output and after any error's
    one line, which stays the first line a script reads)."""
    notes: list[str] = getattr(args, NOTES, None) or []
    notes.append(text)
    setattr(args, NOTES, notes)


class _Deprecated(argparse.Action):
    """An older spelling of an option: it still works, and says what to write instead."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs: Any) -> None:
        self.replacement: str = kwargs.pop("replacement")
        super().__init__(option_strings, dest, **kwargs)

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: str | Sequence[Any] | None,
        option_string: str | None = None,
    ) -> None:
        note(namespace, f"{option_string} is deprecated; use {self.replacement}")
        setattr(namespace, self.dest, values)


def deprecated(container: Any, old: str, new: argparse.Action) -> argparse.Action:
    """Add `old` to `container` (a parser or group) as a deprecated spelling of the option
    `new`: the same destination and type; using it works and says what to use instead."""
    spelling = "/".join(new.option_strings)
    action: argparse.Action = container.add_argument(
        old,
        action=_Deprecated,
        replacement=spelling,
        dest=new.dest,
        type=new.type,
        metavar=new.metavar or new.dest.upper(),
        default=argparse.SUPPRESS,
        help=f"deprecated spelling of {spelling}",
    )
    return action


def add_output(
    parser: argparse.ArgumentParser,
    help: str,
    *,
    folder: bool = False,
    required: bool = False,
    default: Path | None = None,
    old: str | None = None,
) -> argparse.Action:
    """-o/--output: what a command writes, the same flag wherever there is one (a file, or with
    `folder` a folder it writes into), relative to the current folder; `old` is a spelling the
    command used before, kept as a deprecated alias."""
    container: Any = parser.add_mutually_exclusive_group(required=True) if required else parser
    action: argparse.Action = container.add_argument(
        "-o",
        "--output",
        type=output_dir if folder else output_file,
        default=default,
        metavar="DIR" if folder else "FILE",
        help=help,
    )
    if old is not None:
        deprecated(container, old, action)
    return action


def data_folder(text: str) -> Path:
    """A folder of input data, relative to the current folder (made absolute at once, so a
    report and an error name the folder that was read)."""
    return _path(text, "folder").expanduser().resolve()


def add_listen_seconds(parser: argparse.ArgumentParser, help: str) -> None:
    """--duration of a command that listens to the bus for a while and then reports what it saw:
    the same flag and default (2 s, long enough for a 1 Hz health beat) wherever it is."""
    parser.add_argument("--duration", type=seconds(), default=2.0, help=help)


def add_seed(parser: argparse.ArgumentParser, help: str, default: int = 0) -> None:
    """--seed: every command that generates anything takes the same flag with the same range."""
    parser.add_argument("--seed", type=seed, default=default, help=help)


port = number(int, lo=1, hi=65535, what="TCP port")


def shards(text: str) -> int:
    """`--shards`: a number of processes per stage, or `auto` (runtime.shard.shard_count)."""
    try:
        return shard_count(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _parent_problem(folder: Path) -> str | None:
    if not folder.exists():
        return f"folder {folder} does not exist"
    if not folder.is_dir():
        return f"{folder} is not a folder"
    if not os.access(folder, os.W_OK | os.X_OK):
        return f"folder {folder} is not writable"
    return None


def _writable_folder(folder: Path, what: str, *, create: bool) -> None:
    """`folder` exists and is writable, or (with `create`) could be created below a writable
    folder: so no command finds out at its very end that it cannot save its work. Nothing is
    created here: the command makes the folder when it writes into it, so one that fails
    first (no data, bad input) leaves no empty folder behind."""
    if folder.exists() or not create:
        problem = _parent_problem(folder)
    else:
        ancestor = folder.parent
        while not ancestor.exists() and ancestor != ancestor.parent:
            ancestor = ancestor.parent
        problem = _parent_problem(ancestor)
    if problem is not None:
        raise argparse.ArgumentTypeError(f"cannot write {what}: {problem}")


def _path(text: str, noun: str) -> Path:
    if not text.strip() or "\0" in text:
        raise argparse.ArgumentTypeError(f"{text!r} is not a {noun} path")
    try:
        return Path(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r} is not a {noun} path ({exc})") from None


def _checked(check: Callable[[str], Path]) -> Callable[[str], Path]:
    """`check`, with an OSError while looking at the path (a name too long for the file system,
    a loop of links) refused like any other bad path."""

    def parse(text: str) -> Path:
        try:
            return check(text)
        except OSError as exc:
            raise argparse.ArgumentTypeError(f"cannot use {text[:80]!r}: {exc.strerror}") from None

    parse.__name__ = check.__name__
    parse.__doc__ = check.__doc__
    return parse


@_checked
def output_file(text: str) -> Path:
    """A file we may create or overwrite: no folder, not read-only, in an existing writable
    folder (a typo in a folder name is an error, not a new folder)."""
    path = _path(text, "file")
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{path} is a folder; valid: a file path to write")
    if path.exists() and not os.access(path, os.W_OK):
        raise argparse.ArgumentTypeError(f"{path} exists and is not writable")
    _writable_folder(path.parent, str(path), create=False)
    return path


@_checked
def output_dir(text: str) -> Path:
    """A folder we may write into: it exists, or could be made below a writable folder (the
    command makes it, with its parents, once it has something to write)."""
    path = _path(text, "folder")
    _writable_folder(path, f"into {path}", create=True)
    return path


def keyexpr(text: str) -> str:
    """A Zenoh key expression in canonical form (zenoh's own check, so nothing differs later)."""
    import zenoh

    try:
        zenoh.KeyExpr(text)
    except Exception as exc:  # zenoh raises its own ZError
        reason = str(exc).split(" at /", 1)[0]
        raise argparse.ArgumentTypeError(
            f"invalid key expression {text!r} ({reason}); valid: non-empty chunks separated by "
            "'/', '*' or '**' as whole chunks, e.g. beyond/robot/sensors/skeleton"
        ) from None
    return text


def robot_name(text: str) -> str:
    """A robot's name, as the second chunk of its keys (schemas.keys.check_name)."""
    from beyond_self.core.errors import InputError
    from beyond_self.schemas.keys import check_name

    try:
        return check_name("robot", text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_ros2_topic(parser: argparse.ArgumentParser) -> None:
    """`--topic ROLE=/name`: a ROS 2 bag's topic read for a role (runtime.ros2.topics)."""
    parser.add_argument(
        "--topic",
        action="append",
        default=[],
        metavar="ROLE=/NAME",
        help="of a ROS 2 bag, read this topic as ROLE (skeleton, tf, camera, person_camera: "
        "a camera watching the person, through the pose model); repeat. Default: the Azure "
        "Kinect driver's and our topic names, and a colour camera by its type",
    )


def ros2_roles(args: argparse.Namespace) -> dict[str, str]:
    from beyond_self.runtime.ros2.topics import parse_roles

    return parse_roles(getattr(args, "topic", None) or ())


def check_ros2_roles(roles: dict[str, str], info: Any) -> None:
    """`--topic` given for a recording with no ROS 2 topics: refused, not ignored."""
    from beyond_self.core.errors import InputError

    if roles and not info.ros2_topics:
        raise InputError(f"--topic maps a ROS 2 bag's topics; {info.path} has none")
