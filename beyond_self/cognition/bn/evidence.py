"""Evidence: one grammar for typing it, one function that turns it into what the network needs.

Every command that takes evidence and the reasoner's ask queryable go through this module, so a
question asked offline and over the bus gives the same numbers and the same refusals. Values are
named, not listed in definition order, because `beyond ask` has no network at hand (the reasoner
holds it): the `parse_*` functions need none. `build_evidence` is where the network comes in: it
checks every name, orders the soft vectors and turns gesture evidence into soft evidence on the
action, which then may be neither observed nor given as soft evidence too.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

from beyond_self.cognition.bn.model import BayesNet
from beyond_self.cognition.fusion import ACTION, action_vector
from beyond_self.core.errors import InputError, unknown

SUM_TOLERANCE = 1e-6
EVIDENCE_FORM = "VAR=VALUE"
SOFT_FORM = "VAR=value:p,value:p,..."
GESTURE_FORM = "ACTION=p,ACTION=p,..."
_SOFT_EXAMPLE = "--soft Action=grasp:0.2,tap:0.5,touch:0.3"
_GESTURE_EXAMPLE = "--gesture grasp=0.1,tap=0.8,touch=0.1"


@dataclass(frozen=True)
class Evidence:
    """Evidence by name, before any network is at hand (what `AffordanceQuery` carries)."""

    hard: Mapping[str, str] = field(default_factory=dict)
    soft: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    gesture: Mapping[str, float] = field(default_factory=dict)  # empty: no gesture evidence


@dataclass(frozen=True)
class NetworkEvidence:
    """What `BayesNet.query` and `word_probabilities` take: hard values and soft vectors."""

    observed: dict[str, str]
    soft: dict[str, list[float]]


def _split(item: str, flag: str, form: str) -> tuple[str, str]:
    name, sep, rest = item.partition("=")
    if not sep or not name.strip() or not rest.strip():
        raise InputError(f"{flag} expects {form}; got {item!r}")
    return name.strip(), rest.strip()


def _number(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None


def _named_numbers(
    parts: Iterable[str], sep: str, flag: str, expected: str, got: str
) -> dict[str, float]:
    """NAME<sep>p pairs as {NAME: p}, each name once (--soft's values, --gesture's actions); a
    malformed pair is refused with `expected` and the whole argument, `got`."""
    out: dict[str, float] = {}
    for part in parts:
        name, found, number = part.partition(sep)
        p = _number(number)
        if not found or not name.strip() or p is None:
            raise InputError(f"{expected}; got {got!r}")
        if name.strip() in out:
            raise InputError(f"{flag} gives {name.strip()} twice")
        out[name.strip()] = p
    return out


def parse_evidence(items: Iterable[str]) -> dict[str, str]:
    """`["Shape=box", ...]` → {"Shape": "box"}; names are checked by `build_evidence`."""
    out: dict[str, str] = {}
    for item in items:
        name, value = _split(item, "--evidence", EVIDENCE_FORM)
        if name in out:
            raise InputError(f"--evidence gives {name} twice ({out[name]!r} and {value!r})")
        out[name] = value
    return out


def parse_soft(items: Iterable[str]) -> dict[str, dict[str, float]]:
    """`["Action=grasp:0.2,tap:0.8"]` → {"Action": {"grasp": 0.2, "tap": 0.8}}."""
    out: dict[str, dict[str, float]] = {}
    for item in items:
        name, text = _split(item, "--soft", SOFT_FORM)
        parts = [part.strip() for part in text.split(",")]
        if all(":" not in part and _number(part) is not None for part in parts):
            raise InputError(
                f"--soft names each value now, {SOFT_FORM} (e.g. {_SOFT_EXAMPLE}); "
                f"the positional form VAR=p1,p2,... is gone; got {item!r}"
            )
        dist = _named_numbers(
            parts,
            ":",
            f"--soft {name}",
            f"--soft {name}: expected comma-separated value:p pairs with p a number ({SOFT_FORM})",
            text,
        )
        if name in out:
            raise InputError(f"--soft gives {name} twice")
        out[name] = dist
    return out


def parse_gesture(items: Sequence[str]) -> dict[str, float]:
    """`["grasp=0.1,tap=0.8,touch=0.1"]` → {"grasp": 0.1, ...}; no items, no gesture evidence.

    A list, so that the two-argument form of old (`--gesture MODELS LOG`) arrives here and is
    refused with a message naming what replaced it, instead of being half-parsed."""
    if not items:
        return {}
    if len(items) > 1 or "=" not in items[0]:
        raise InputError(
            f"--gesture takes P_HMM(A | G) as one {GESTURE_FORM} (e.g. {_GESTURE_EXAMPLE}); "
            "to run the recogniser over a hand log give --gesture-log MODELS LOG "
            "(bn query|words, describe); "
            f"got {' '.join(items)!r}"
        )
    return _named_numbers(
        items[0].split(","),
        "=",
        "--gesture",
        f"--gesture expects comma-separated ACTION=p pairs with p a number ({GESTURE_FORM})",
        items[0],
    )


def _soft_vector(model: BayesNet, name: str, dist: Mapping[str, float]) -> list[float]:
    if name not in model.values:
        raise unknown("soft-evidence variable", name, model.variables)
    values = model.values[name]
    extra = [v for v in dist if v not in values]
    if extra:
        raise unknown(f"value of {name}", extra[0], values)
    probs = [float(dist.get(v, 0.0)) for v in values]
    if any(not (math.isfinite(p) and 0.0 <= p <= 1.0) for p in probs):
        shown = ", ".join(f"{v}:{p:g}" for v, p in dist.items())
        raise InputError(f"--soft {name}: probabilities must lie in [0, 1]; got {shown}")
    total = sum(probs)
    if abs(total - 1.0) > SUM_TOLERANCE:
        raise InputError(
            f"--soft {name}: probabilities sum to {total:.9g}; they must sum to 1 "
            f"(within {SUM_TOLERANCE:g}) over {', '.join(values)}"
        )
    return probs


def build_evidence(model: BayesNet, evidence: Evidence) -> NetworkEvidence:
    """Evidence by name → hard values and soft vectors in `model`'s definition order.

    Gesture evidence becomes soft evidence on the action (`cognition.fusion.action_vector`,
    the article's P_comb), so with it the action may be neither observed nor soft evidence."""
    observed: dict[str, str] = {}
    for name, value in evidence.hard.items():
        model.definition[name].index(value)  # unknown variable or value: InputError
        observed[name] = value
    soft = {name: _soft_vector(model, name, dist) for name, dist in evidence.soft.items()}
    if evidence.gesture:
        if ACTION not in model.values:
            raise InputError(f"the network has no {ACTION} node; gesture evidence needs one")
        if ACTION in observed:
            raise InputError(
                f"the action comes from the gesture evidence, so it is never observed: "
                f"drop {ACTION}={observed[ACTION]} from --evidence"
            )
        if ACTION in soft:
            raise InputError(
                f"the action comes from the gesture evidence: drop {ACTION} from --soft "
                "(give the action one way)"
            )
        soft[ACTION] = action_vector(model, evidence.gesture).tolist()
    return NetworkEvidence(observed, soft)
