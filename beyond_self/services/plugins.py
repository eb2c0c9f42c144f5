"""A live source plug-in for the ingest (`module:function`) and the skeleton items it yields."""

from __future__ import annotations

import importlib
from collections.abc import AsyncIterator, Callable, Mapping, Sequence
from typing import Any, cast

from beyond_self.core.errors import InputError
from beyond_self.schemas import Joint


def joints_of(items: Mapping[str, Sequence[float]]) -> dict[str, Joint]:
    """Skeleton joints from a plug-in's `joint -> (x, y, z)` or `(x, y, z, confidence)`."""
    joints = {}
    for name, p in items.items():
        x, y, z = (float(v) for v in p[:3])
        joints[name] = Joint(position=(x, y, z), confidence=float(p[3]) if len(p) > 3 else 1.0)
    return joints


def load_plugin(spec: str) -> Callable[[], AsyncIterator[tuple[str, Any]]]:
    module_name, sep, attr = spec.partition(":")
    if not sep:
        raise InputError(f"plug-in {spec!r}; valid: module:function")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise InputError(f"plug-in module {module_name!r} cannot be imported: {exc}") from None
    fn = getattr(module, attr, None)
    if not callable(fn):
        raise InputError(f"plug-in {spec!r}: {module_name} has no function {attr!r}")
    return cast("Callable[[], AsyncIterator[tuple[str, Any]]]", fn)
