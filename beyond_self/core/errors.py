"""The one exception type for bad input anywhere in the project.

Why one type: the CLI, the services and the tests all need to tell "the user gave us something
wrong" (print one line, exit 2 / count it and keep running) apart from a bug (traceback). Every
message is a single line saying what was wrong and what is valid.
"""

from __future__ import annotations

from pathlib import Path


class InputError(ValueError):
    """Bad input: a malformed file or message, an unknown variable or value, a missing file."""

    def __init__(self, message: str) -> None:
        super().__init__(" ".join(message.split()))  # always one line


def unknown(kind: str, got: object, valid: list[str] | tuple[str, ...]) -> InputError:
    """An InputError for a name that is not among the valid ones, listing them."""
    shown = ", ".join(map(str, valid[:60])) + (", ..." if len(valid) > 60 else "")
    return InputError(f"unknown {kind} {got!r}; valid: {shown}")


def read_text(path: Path, what: str, *, missing: str = "") -> str:
    """The UTF-8 text of the file `path`, or an InputError naming it as `what` (and, when it does
    not exist, adding `missing`: how to get one)."""
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"{what} {path} does not exist{missing}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read {what} {path}: {exc}") from None
