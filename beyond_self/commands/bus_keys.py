"""The key argument of the bus tools (`hz`, `bw`, `info`, `pub`): a known key of ours, or a
key expression with wildcards. Anything else is almost always a typo, and a tool that silently
listens to nothing for ever does not say so; this one says which keys exist."""

from __future__ import annotations

from beyond_self.core.errors import unknown
from beyond_self.schemas.base import Message
from beyond_self.schemas.keys import HEALTH, STREAMS, Keys, type_for_key


def is_pattern(key: str) -> bool:
    return "*" in key or "$*" in key


def known_keys(keys: Keys) -> list[str]:
    return [f"{keys.root}/{suffix}" for suffix, _ in STREAMS.values()] + [
        f"{keys.root}/{HEALTH}/<service>"
    ]


def check_key(key: str, keys: Keys, *, concrete: bool = False) -> type[Message] | None:
    """The type `key` carries (None for a pattern); InputError listing the valid keys when it
    is neither ours nor a pattern (or a pattern where a concrete key is needed)."""
    cls = type_for_key(key)
    if cls is None and (concrete or not is_pattern(key)):
        raise unknown("key", key, known_keys(keys) + ([] if concrete else ["or a pattern with *"]))
    return cls
