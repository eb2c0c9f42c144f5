"""A robot's state folder on this machine: what outlives every process of a run.

`$BEYOND_STATE_DIR/<robot>/<service>/` holds a service's snapshots, its source log and its last
ledger (`ledger.msgpack`: what it handled and where its successor starts). A service started
where such records exist takes them as those of instances that died (the whole deployment
killed: no one on the bus remembers them), and goes on from there. `beyond up` gives its services
the folder and keeps its own record beside theirs (runtime.resilience.run_state).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

import msgspec

from beyond_self.schemas.messages import Ledger

STATE_DIR_VAR = "BEYOND_STATE_DIR"
LEDGER_FILE = "ledger.msgpack"


def state_root() -> Path | None:
    """$BEYOND_STATE_DIR (None when it is not set: services keep no state on disk)."""
    base = os.environ.get(STATE_DIR_VAR)
    return Path(base) if base else None


def state_dir(robot: str, service: str) -> Path | None:
    """The state folder of `service` of `robot` on this machine (None: no state on disk)."""
    root = state_root()
    return root / robot / service if root is not None else None


def write_atomically(path: Path, data: bytes, *, sync: bool) -> None:
    """Replace `path` with `data` whole: a kill leaves the old file or the new one, never half;
    `sync` also survives a power cut (an fsync of the file and of its folder: milliseconds)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with temporary.open("wb") as f:
        f.write(data)
        if sync:
            f.flush()
            os.fsync(f.fileno())
    os.replace(temporary, path)
    if sync:
        folder = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(folder)
        finally:
            os.close(folder)


class LedgerFile:
    """A service's last ledger, kept in its state folder (written on every publish: a few KB)."""

    def __init__(self, folder: Path) -> None:
        self.path = folder / LEDGER_FILE

    def save(self, ledger: Ledger) -> None:
        # a kill cannot tear it; a power cut may lose the last second (snapshots are synced)
        write_atomically(self.path, msgspec.msgpack.encode(ledger), sync=False)

    def siblings(self) -> Iterator[Ledger]:
        """The ledgers kept by every service of this robot on this machine (this one's too);
        one that does not decode (another version's, a torn disk) is passed over."""
        robot = self.path.parent.parent
        for path in sorted(robot.glob(f"*/{LEDGER_FILE}")):
            with contextlib.suppress(OSError, msgspec.DecodeError, msgspec.ValidationError):
                yield msgspec.msgpack.decode(path.read_bytes(), type=Ledger)
