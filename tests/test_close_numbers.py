"""The tolerance the reproduced figures are compared with forgives another machine's last digits
and nothing else (tests/close_numbers.py)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest
from close_numbers import mismatches

FIGURES = Path(__file__).resolve().parent.parent / "docs" / "science" / "figures"

# drift seen between OpenBLAS kernels (SkylakeX, Sandybridge, Prescott) on `beyond reproduce`
SEEN = [
    (-11.158912223872324, -11.158912223872344),
    (0.0010699649499886243, 0.0010699649499885972),
    (5.90271214354775e-77, 5.9027121435459056e-77),
    (-1.1102230246251565e-16, -2.220446049250313e-16),  # a difference of equal probabilities
]


@pytest.mark.parametrize(("a", "b"), SEEN)
def test_the_drift_of_another_kernel_is_forgiven(a: float, b: float) -> None:
    assert mismatches({"x": [a]}, {"x": [b]}) == []


@pytest.mark.parametrize(
    ("actual", "expected", "named"),
    [
        ({"p": 0.5000001}, {"p": 0.5}, "/p"),  # a change in the 7th digit
        ({"p": 1e-9}, {"p": 0.0}, "/p"),  # a probability that was zero
        ({"p": -186.6825}, {"p": -186.6826}, "/p"),
        ({"s": [["the robot taps", 0.1]]}, {"s": [["the robot pokes", 0.1]]}, "/s[0][0]"),
        ({"a": 1, "b": 2}, {"b": 2, "a": 1}, "keys"),  # the order of keys is structure too
        ({"n": [1.0, 2.0]}, {"n": [1.0]}, "items"),
        ({"k": 3}, {"k": 3.0}, "int"),
        ({"same": True}, {"same": False}, "/same"),
        ({"x": math.nan}, {"x": 0.0}, "/x"),
    ],
)
def test_anything_beyond_drift_is_a_difference_named_by_its_path(
    actual: Any, expected: Any, named: str
) -> None:
    found = mismatches(actual, expected)
    assert len(found) == 1 and named in found[0], found


def test_the_committed_figures_match_themselves_and_not_a_changed_copy() -> None:
    committed = json.loads((FIGURES / "results.json").read_text(encoding="utf-8"))
    assert mismatches(committed, json.loads(json.dumps(committed))) == []
    changed = json.loads(json.dumps(committed))
    changed["exp1_tap_threshold"] *= 1 + 1e-6
    assert [m.split(":")[0] for m in mismatches(changed, committed)] == ["/exp1_tap_threshold"]
