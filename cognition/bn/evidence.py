"""Evidence as people type it (`VAR=VALUE`, `VAR=p1,p2,...`), checked against a network.

Shared by every command that takes evidence, so the syntax and the messages are the same
everywhere. Soft evidence typed by a person is a distribution over the variable's values (in
definition order) and must sum to 1 within `SUM_TOLERANCE`; the library API itself accepts any
likelihood vector.
"""

from __future__ import annotations

from collections.abc import Iterable

from cognition.bn.definition import NetworkDefinition
from core.errors import InputError

SUM_TOLERANCE = 1e-6


def _split(item: str, flag: str, form: str) -> tuple[str, str]:
    name, sep, rest = item.partition("=")
    if not sep or not name or not rest:
        raise InputError(f"{flag} expects {form}; got {item!r}")
    return name.strip(), rest.strip()


def parse_evidence(items: Iterable[str], definition: NetworkDefinition) -> dict[str, str]:
    """`["Shape=box", ...]` → {"Shape": "box"}; unknown variables or values are InputErrors."""
    out: dict[str, str] = {}
    for item in items:
        name, value = _split(item, "--evidence", "VAR=VALUE")
        var = definition[name]
        var.index(value)
        if name in out:
            raise InputError(f"--evidence gives {name} twice ({out[name]!r} and {value!r})")
        out[name] = value
    return out


def parse_soft(
    items: Iterable[str], definition: NetworkDefinition, normalised: bool = True
) -> dict[str, list[float]]:
    """`["Action=0.2,0.7,0.1"]` → {"Action": [0.2, 0.7, 0.1]}, one number per value."""
    out: dict[str, list[float]] = {}
    for item in items:
        name, text = _split(item, "--soft", "VAR=p1,p2,...")
        var = definition[name]
        try:
            probs = [float(x) for x in text.split(",")]
        except ValueError:
            raise InputError(
                f"--soft {name}: expected comma-separated numbers; got {text!r}"
            ) from None
        if len(probs) != var.card:
            raise InputError(
                f"--soft {name}: {len(probs)} numbers given; {name} has {var.card} values "
                f"({', '.join(var.values)}), give one probability each"
            )
        if any(not 0.0 <= p <= 1.0 for p in probs):
            raise InputError(f"--soft {name}: probabilities must lie in [0, 1]; got {text}")
        if normalised and abs(sum(probs) - 1.0) > SUM_TOLERANCE:
            raise InputError(
                f"--soft {name}: probabilities sum to {sum(probs):.9g}; they must sum to 1 "
                f"(within {SUM_TOLERANCE:g})"
            )
        if name in out:
            raise InputError(f"--soft gives {name} twice")
        out[name] = probs
    return out
