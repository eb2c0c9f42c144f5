"""Snapshots of a service's state, taken by its base, on its own machine: the newest few, each
written atomically.

A piece of cognition that keeps state between messages (the gesture tracker, the object watch)
says what a successor needs as a `Restorable` (core.restorable): the first input stamp it needs
again and the gestures started by then. The base asks for it after every message it handles
(`Snapshots.offer`); when it has moved, it is told in the service's ledger (a successor anywhere
on the bus finds it) and stored in the service's state folder: written to a temporary file,
synced, renamed into place and the folder synced, so a SIGKILL or a power cut leaves the old
snapshot or the new one, never half. On start the base chooses the one to restore (`chosen`).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any, Generic, TypeVar

import msgspec

from beyond_self.core.restorable import Restorable
from beyond_self.runtime.resilience.ledger import Keeper, Position
from beyond_self.runtime.resilience.state import write_atomically

S = TypeVar("S", bound=Restorable)

# checkpoints a producer keeps, one per gesture count, for a successor to go back to
CHECKPOINTS_KEPT = 8


def per_gesture(resume: Mapping[str, int], name: str) -> dict[int, int]:
    """What a predecessor left per gesture count as "<name>@N" (`at_gestures`): N -> value."""
    prefix = f"{name}@"
    return {
        int(key.removeprefix(prefix)): value
        for key, value in resume.items()
        if key.startswith(prefix) and key.removeprefix(prefix).isdigit()
    }


def at_gestures(name: str, values: Mapping[int, int]) -> dict[str, int]:
    """`values` per gesture count as a ledger's resume entries, "<name>@N"."""
    return {f"{name}@{n}": value for n, value in values.items()}


def keep_newest(history: dict[int, Any]) -> None:
    """Drop all but the CHECKPOINTS_KEPT highest gesture counts of `history`."""
    for old in sorted(history)[:-CHECKPOINTS_KEPT]:
        del history[old]


KEEP = 4
EVERY_S = 2.0  # a snapshot stored on the machine at least this often (wall time: the machine's)
GESTURES = "gestures"  # the ledger entry of a snapshot's gesture count (`Restorable.gestures`)


class Positioned(msgspec.Struct, frozen=True):
    """A snapshot as stored: its number (one more than the last), the input position it
    reflects (sensor key -> first stamp needed again) and the state itself, encoded."""

    number: int
    positions: dict[str, int]
    state: bytes


class SnapshotStore:
    """`save` a state, `newest` to restore one; numbered files `<number>.snap`."""

    def __init__(self, folder: Path, keep: int = KEEP) -> None:
        self.folder = folder / "snapshots"
        self.folder.mkdir(parents=True, exist_ok=True)
        self.keep = keep
        self.bytes_written = 0
        found = self.numbers()
        self.number = found[-1] if found else 0

    def numbers(self) -> list[int]:
        return sorted(int(p.stem) for p in self.folder.glob("*.snap") if p.stem.isdigit())

    def save(self, state: msgspec.Struct, positions: dict[str, int]) -> int:
        """Store `state` durably as the newest snapshot; its size in bytes."""
        self.number += 1
        data = msgspec.msgpack.encode(
            Positioned(self.number, dict(positions), msgspec.msgpack.encode(state))
        )
        write_atomically(self.folder / f"{self.number:010d}.snap", data, sync=True)
        for old in self.numbers()[: -self.keep]:
            with contextlib.suppress(FileNotFoundError):
                (self.folder / f"{old:010d}.snap").unlink()
        self.bytes_written += len(data)
        return len(data)

    def newest(self, cls: type[S]) -> tuple[S, dict[str, int]] | None:
        """The newest snapshot that decodes as `cls`, with its positions (None: none)."""
        for number in reversed(self.numbers()):
            path = self.folder / f"{number:010d}.snap"
            try:
                stored = msgspec.msgpack.decode(path.read_bytes(), type=Positioned)
                return msgspec.msgpack.decode(stored.state, type=cls), stored.positions
            except (OSError, msgspec.DecodeError, msgspec.ValidationError):
                continue  # another version's, or gone: an older one may do
        return None


class Snapshots(Generic[S]):
    """A service's snapshots of one state type, taken by the base (`Service.keep_state`): told
    with its ledger (so a successor anywhere on the bus, a fleet's standby, finds them: the
    newest, and the newest at each of the last gesture counts, as the state's integer fields)
    and stored on its machine (`SnapshotStore`: on a new gesture count and at most every
    `every_s` seconds otherwise). Its input position is the state's stamp on each of `inputs`."""

    def __init__(
        self,
        cls: type[S],
        keeper: Keeper,
        store: SnapshotStore | None,
        said_key: str,
        inputs: Sequence[str],
        every_s: float = EVERY_S,
    ) -> None:
        self.cls = cls
        self.keeper = keeper
        self.store = store
        self.said_key = said_key
        self.inputs = list(inputs)
        self.every_s = every_s
        self.fields = [f for f in msgspec.structs.fields(cls) if f.type is int]
        resume = keeper.predecessor()
        self.history: dict[int, S] = {}  # gesture count -> the newest snapshot at it
        for n in per_gesture(resume, GESTURES):
            state = self._state(resume, f"@{n}")
            if state is not None:
                self.history[n] = state
        self.gestures = resume.get(GESTURES, 0)
        self.newest = self._state(resume, "")
        self.last: S | None = None  # the last one offered
        self._stored_at = -float("inf")
        self.taken_count = 0
        self.stored: Future[int] | None = None  # the last save handed to the writer
        # one thread writes them, in order: an fsync takes milliseconds, not the event loop's
        self._writer = ThreadPoolExecutor(1, "snapshots") if store is not None else None

    def _state(self, resume: Mapping[str, int], suffix: str) -> S | None:
        values: dict[str, int] = {}
        for f in self.fields:
            value = resume.get(f.name + suffix)
            if value is None:
                return None
            values[f.name] = value
        return self.cls(**values)

    def chosen(self, restarted: bool) -> S | None:
        """The snapshot to restore: the predecessor's newest, or, when the gestures it had seen
        are not all said yet (a workstation taken over: the outputs in between died with it),
        the newest one before the oldest gesture not said; else, restarted with no record on
        the bus, the newest on this machine. None: start afresh."""
        if self.newest is None:
            if not restarted or self.store is None:
                return None
            found = self.store.newest(self.cls)
            return None if found is None else found[0]
        unsaid = self.keeper.unsaid(self.said_key, range(1, self.gestures + 1))
        if not self.history or not unsaid:
            return self.newest
        before = [n for n in self.history if n < min(unsaid)] or [min(self.history)]
        return self.history[max(before)]

    def offer(self, state: S | None) -> None:
        """The service's state now (None: none yet), after a message: taken if it moved."""
        if state is not None and state != self.last:
            self.last = state
            self.taken(state)

    def positions(self, state: S) -> dict[str, int]:
        """Where the inputs are played again from for `state`: sensor key -> stamp."""
        return dict.fromkeys(self.inputs, state.stamp)

    def taken(self, state: S) -> None:
        """`state` is this service's newest snapshot."""
        gestures = state.gestures
        first_at_count = gestures not in self.history
        self.history[gestures] = state
        keep_newest(self.history)
        stamps: dict[str, int] = {}
        counts: dict[str, int] = {}
        for name, value in msgspec.structs.asdict(state).items():
            if not isinstance(value, int):
                continue
            kept = stamps if name.endswith("stamp") else counts
            kept[name] = value
            kept |= at_gestures(name, {n: getattr(s, name) for n, s in self.history.items()})
        # where a successor goes back to derive gesture N again (schemas.InputPosition)
        at = {Position(k, n + 1): s.stamp for n, s in self.history.items() for k in self.inputs}
        newest = {Position(k): stamp for k, stamp in self.positions(state).items()}
        self.keeper.checkpoint(stamps, counts, {**newest, **at})
        self.taken_count += 1
        now = time.monotonic()
        if self._writer is not None and (first_at_count or now - self._stored_at >= self.every_s):
            assert self.store is not None
            self._stored_at = now
            self.stored = self._writer.submit(self.store.save, state, self.positions(state))
        if first_at_count:
            # told at once, not with the next health report: at rate max a second of wall time
            # is many gestures, and a successor needs a snapshot its source still has input for
            self.keeper.publish()
