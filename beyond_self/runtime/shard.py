"""Which shard of a sharded fleet workstation serves a robot (`beyond up --shards N`).

A workstation stage may run as N processes, each a normal fleet service (runtime/fleet.py)
serving the robots whose name hashes to it: a pure function of the name and N, the same in every
process and every Python run (BLAKE2b, never Python's salted `hash()`), so two shards never
serve one robot, and a restarted shard takes back exactly its own robots. Each shard has its own
host name (`<workstation>.shard<K>`), under which it is alive and answers health.
Why no shard stands by for a sibling: docs/decisions.md (2026-12-07).
"""

from __future__ import annotations

import hashlib
import os
import re
from dataclasses import dataclass

from beyond_self.core.errors import InputError

SHARDS_MAX = 256  # far above any machine's cores: more is a typo
_SHARD = re.compile(r"^(\d+)/(\d+)$")


def shard_of(robot: str, count: int) -> int:
    """The shard (0 to `count` - 1) that serves robot `robot` among `count`."""
    digest = hashlib.blake2b(robot.encode(), digest_size=8).digest()
    return int.from_bytes(digest, "big") % count


@dataclass(frozen=True)
class Shard:
    """Shard `index` of `count`: it serves the robots `shard_of` gives it."""

    index: int
    count: int

    def __post_init__(self) -> None:
        if not 1 <= self.count <= SHARDS_MAX or not 0 <= self.index < self.count:
            raise InputError(
                f"shard {self.index}/{self.count}; valid: K/N with 0 <= K < N <= {SHARDS_MAX}"
            )

    def serves(self, robot: str) -> bool:
        return shard_of(robot, self.count) == self.index

    def host(self, workstation: str) -> str:
        """This shard's own name on the bus, as a host of its workstation `workstation`."""
        return f"{workstation}.shard{self.index}"

    def __str__(self) -> str:
        return f"{self.index}/{self.count}"


def parse_shard(text: str) -> Shard:
    """`K/N` (`beyond service NAME --robots PATTERN --shard K/N`) as a Shard."""
    found = _SHARD.match(text.strip())
    if found is None:
        raise InputError(f"shard {text!r}; valid: K/N with 0 <= K < N <= {SHARDS_MAX}, e.g. 0/2")
    return Shard(int(found[1]), int(found[2]))


def usable_cores() -> int:
    """The cores this process may run on (its affinity, which a container or taskset limits)."""
    if hasattr(os, "sched_getaffinity"):  # Linux
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1


def shard_count(text: str) -> int:
    """`--shards`: a number of shards from 1 to SHARDS_MAX, or `auto` (usable_cores)."""
    if text.strip() == "auto":
        return min(usable_cores(), SHARDS_MAX)
    try:
        count = int(text)
    except ValueError:
        count = 0
    if not 1 <= count <= SHARDS_MAX:
        raise InputError(
            f"{text!r} is not a number of shards; valid: 1 to {SHARDS_MAX} processes per "
            "stage, or auto (one per core this process may use)"
        )
    return count
