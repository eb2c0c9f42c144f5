"""A side effect's commit log: what a `once=` subscription has done, written before it is done.

The bus ledger reaches the others a moment after a sentence is said, so a service whose handling
is a side effect (the speech service, the ROS 2 bridge, a user's drop-in) keeps a log of its own
that cannot lag: one line per gesture acted on, appended before the effect. Given to
`Service.subscribe(..., once=log)`, the base reads back the lines its run wrote (from the log's
size when the run's first instance began, kept in the ledger's checkpoint) and takes those
gestures as handled: a restarted instance does not act on them again.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

from beyond_self.runtime.log import event
from beyond_self.runtime.resilience.ledger import Keeper
from beyond_self.schemas.base import Message
from beyond_self.schemas.identity import Identity
from beyond_self.schemas.keys import split_key
from beyond_self.schemas.messages import (
    Description,
    GestureObject,
    ObjectEffects,
    WordProbabilities,
)

LOG_START = "log_start"  # checkpoint: the log's size when this run's first instance began

# the per-gesture kind (schemas.identity) a line of the log stands for, per message type
KINDS: dict[type[Message], str] = {
    Description: "description",
    WordProbabilities: "words",
    ObjectEffects: "effects",
    GestureObject: "object",
}


class EffectLog:
    """One line per effect done (stamp, gesture, a file or '-', text), append-only."""

    def __init__(self, path: Path, *, sync: bool = True) -> None:
        self.path = path
        self.sync = sync  # also survive a power loss, not only a kill (a synced write costs ms)

    def size(self) -> int:
        return self.path.stat().st_size if self.path.exists() else 0

    def gestures_since(self, offset: int) -> list[int]:
        """The gestures of the complete lines written from byte `offset` on (a file that
        shrank since, replaced by hand, holds none of them)."""
        if self.size() <= offset:
            return []
        with self.path.open("rb") as f:
            f.seek(offset)
            lines = f.read().split(b"\n")[:-1]  # the last piece is not a complete line
        fields = (line.split(b"\t") for line in lines)
        return [int(f[1]) for f in fields if len(f) >= 4 and f[1].isdigit()]

    def append(self, stamp: int, gesture: int, wav: str, text: str) -> None:
        """One write on an append-only descriptor (a SIGKILL cannot tear it), then synced
        (`sync`); on a line of its own even after one a power loss cut short."""
        line = f"{stamp}\t{gesture}\t{wav}\t{text}\n".encode()
        fd = os.open(self.path, os.O_RDWR | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            size = os.fstat(fd).st_size
            if size and os.pread(fd, 1, size - 1) != b"\n":
                line = b"\n" + line
            os.write(fd, line)
            if self.sync:
                os.fsync(fd)
        finally:
            os.close(fd)


def take_over(
    keeper: Keeper, key: str, cls: type[Message], log: EffectLog, logger: logging.Logger
) -> None:
    """A restarted instance: the gestures of its run's part of `log` count as handled on `key`.
    The first instance: its run's part starts at the log's present end, kept in its
    checkpoint (LOG_START)."""
    kind = KINDS.get(cls)
    if kind is None:
        valid = ", ".join(sorted(c.__name__ for c in KINDS))
        raise TypeError(f"once= with a log takes a per-gesture result; got {cls.__name__}; "
                        f"valid: {valid}")  # fmt: skip
    start = keeper.predecessor().get(LOG_START)
    if start is not None:
        split = split_key(key)
        robot = split[0] if split is not None else ""
        gestures = log.gestures_since(start)
        for gesture in gestures:
            keeper.handled.add(key, Identity(robot, gesture, kind))
        event(logger, logging.INFO, "took the log of what was said", said=len(gestures))
    else:
        start = log.size()
    keeper.checkpoint({}, {LOG_START: start})
