"""Figures compared as another machine computes them: every float within a tolerance, all else
exact.

Another CPU, or another OpenBLAS kernel on the same CPU (`OPENBLAS_CORETYPE`), sums in another
order and changes the last one or two digits of a figure (seen: relative 3e-13 on a posterior,
1e-16 absolute on a difference of probabilities that is zero). A reproduced figure therefore
matches its committed value within `RELATIVE` (1e-9: a thousand times that drift, a million
times finer than any digit the pages print), or within `ABSOLUTE` (1e-12) for the values near
zero whose drift is absolute. Keys, their order, lengths, strings, integers and booleans are
compared exactly: only float drift is forgiven.
"""

from __future__ import annotations

import math
from typing import Any

RELATIVE = 1e-9
ABSOLUTE = 1e-12


def float_close(a: float, b: float, rel: float = RELATIVE, abs_: float = ABSOLUTE) -> bool:
    """Within the tolerance; NaN matches NaN (a figure that is undefined on both machines)."""
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    return math.isclose(a, b, rel_tol=rel, abs_tol=abs_)


def mismatches(
    actual: Any, expected: Any, path: str = "", rel: float = RELATIVE, abs_: float = ABSOLUTE
) -> list[str]:
    """Every place where two JSON-like values differ by more than float drift, named by path."""
    where = path or "/"
    if isinstance(expected, float) and isinstance(actual, float):
        if float_close(actual, expected, rel, abs_):
            return []
        return [f"{where}: {actual!r} != {expected!r} (beyond rel {rel:g}, abs {abs_:g})"]
    if type(actual) is not type(expected):
        return [f"{where}: {type(actual).__name__} {actual!r} != {type(expected).__name__}"]
    if isinstance(expected, dict):
        if list(actual) != list(expected):
            return [f"{where}: keys {list(actual)} != {list(expected)}"]
        out: list[str] = []
        for key in expected:
            out += mismatches(actual[key], expected[key], f"{path}/{key}", rel, abs_)
        return out
    if isinstance(expected, list | tuple):
        if len(actual) != len(expected):
            return [f"{where}: {len(actual)} items != {len(expected)}"]
        out = []
        for i, (a, e) in enumerate(zip(actual, expected, strict=True)):
            out += mismatches(a, e, f"{path}[{i}]", rel, abs_)
        return out
    return [] if actual == expected else [f"{where}: {actual!r} != {expected!r}"]


def assert_close(actual: Any, expected: Any, what: str = "") -> None:
    """Fail naming the first few places that differ beyond float drift."""
    found = mismatches(actual, expected)
    assert not found, f"{what}: {len(found)} difference(s):\n" + "\n".join(found[:10])
