"""P_comb (SPEC.md fusion): the literal formulas equal soft evidence on Action, to 1e-12."""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from beyond_self.cognition.bn import (
    BayesNet,
    learn_network,
    load_bag,
    load_definition,
    synthetic_dataset,
)
from beyond_self.cognition.fusion import fuse, fuse_marginals, fuse_words
from beyond_self.core.errors import InputError

# these figures are computed again under a second OpenBLAS kernel (Makefile: numeric)
pytestmark = pytest.mark.numeric

AFFORDANCE = ("Color", "Shape", "Size", "ObjVel", "ObjHandVel", "HandVel", "Contact")


@functools.cache
def synthetic_model() -> BayesNet:
    return learn_network(synthetic_dataset())


@st.composite
def fusion_case(draw: st.DrawFn) -> tuple[dict[str, str], list[str], list[float]]:
    model = synthetic_model()
    names = draw(st.permutations(AFFORDANCE))
    n_obs = draw(st.integers(0, 3))
    observed = {n: draw(st.sampled_from(model.values[n])) for n in names[:n_obs]}
    rest = [n for n in (*names[n_obs:], *model.words[:5], "Action") if n not in observed]
    query = draw(st.lists(st.sampled_from(rest), min_size=1, max_size=3, unique=True))
    p_hmm = draw(st.lists(st.floats(0.0, 1.0), min_size=3, max_size=3).filter(lambda v: sum(v) > 0))
    return observed, query, p_hmm


@settings(max_examples=60, deadline=None)
@given(fusion_case())
def test_formula_equals_soft_evidence(case: tuple[dict[str, str], list[str], list[float]]) -> None:
    observed, query, p_hmm = case
    model = synthetic_model()
    try:
        soft = fuse(model, query, observed, p_hmm, method="soft")
    except InputError:  # impossible evidence: the formula must refuse it too
        with pytest.raises(InputError):
            fuse(model, query, observed, p_hmm, method="formula")
        return
    formula = fuse(model, query, observed, p_hmm, method="formula")
    assert soft.variables == formula.variables
    np.testing.assert_allclose(soft.table, formula.table, rtol=0, atol=1e-12)
    assert abs(float(formula.table.sum()) - 1.0) < 1e-12


@settings(max_examples=25, deadline=None)
@given(fusion_case())
def test_word_fusion_formula_equals_soft(
    case: tuple[dict[str, str], list[str], list[float]],
) -> None:
    observed, _, p_hmm = case
    model = synthetic_model()
    try:
        soft = fuse_words(model, observed, p_hmm, method="soft")
    except InputError:
        return
    formula = fuse_words(model, observed, p_hmm, method="formula")
    assert soft.keys() == formula.keys()
    for word in soft:
        assert abs(soft[word] - formula[word]) < 1e-12, word


@settings(max_examples=60, deadline=None)
@given(fusion_case())
def test_marginals_per_frame_equal_fusing_each_variable(
    case: tuple[dict[str, str], list[str], list[float]],
) -> None:
    """The reasoner's per-frame path (tables kept per observed set) against `fuse` per variable,
    asked twice so the second answer comes from the kept tables."""
    observed, query, p_hmm = case
    model = synthetic_model()
    for _ in range(2):
        try:
            expected = {q: fuse(model, q, observed, p_hmm).marginal(q) for q in query}
        except InputError as exc:  # impossible evidence: refused the same way
            with pytest.raises(InputError, match="zero probability") as refused:
                fuse_marginals(model, query, observed, p_hmm)
            assert "zero probability" in str(exc), (str(exc), str(refused.value))
            return
        got = fuse_marginals(model, query, observed, p_hmm)
        assert list(got) == query
        for q in query:
            assert list(got[q]) == list(expected[q]), q
            np.testing.assert_allclose(list(got[q].values()), list(expected[q].values()),
                                       rtol=0, atol=1e-12)  # fmt: skip


def test_certain_gesture_equals_observing_the_action() -> None:
    model = synthetic_model()
    fused = fuse(model, "ObjVel", {"Shape": "circle"}, {"grasp": 0, "tap": 1, "touch": 0})
    direct = model.query("ObjVel", {"Shape": "circle", "Action": "tap"})
    np.testing.assert_allclose(fused.table, direct.table, atol=1e-12)


def test_uniform_gesture_changes_nothing() -> None:
    model = synthetic_model()
    fused = fuse(model, ["Action", "ObjVel"], {"Shape": "box"}, [1, 1, 1])
    direct = model.query(["Action", "ObjVel"], {"Shape": "box"})
    np.testing.assert_allclose(fused.table, direct.table, atol=1e-12)


def test_observed_action_and_bad_evidence_are_clear_errors() -> None:
    model = synthetic_model()
    with pytest.raises(InputError, match="never observed directly"):
        fuse(model, "ObjVel", {"Action": "tap"}, [1, 1, 1])
    with pytest.raises(InputError, match="valid: grasp, tap, touch"):
        fuse(model, "ObjVel", {}, {"grasp": 0.5, "kick": 0.5})
    with pytest.raises(InputError, match="lacks action"):
        fuse(model, "ObjVel", {}, {"grasp": 0.5, "tap": 0.5})
    with pytest.raises(InputError, match="needs 3 probabilities"):
        fuse(model, "ObjVel", {}, [0.5, 0.5])


def test_real_network_tap_evidence_overrides_touch_prior(shared_data: Path) -> None:
    # Experiment 1 of the article: the network alone favours touch for a small slow sphere, and
    # confident gesture evidence for tap turns the fused belief to tap.
    base = shared_data / "salvi2012"
    definition = load_definition(base / "networkDefinition.txt")
    model = learn_network(load_bag(base / "sent-1-5_lab_aff_bag.txt", definition))
    observed = {"Size": "small", "Shape": "circle", "ObjVel": "slow"}
    alone = model.query("Action", observed).marginal("Action")
    assert max(alone, key=alone.__getitem__) == "touch"
    fused = fuse(model, "Action", observed, {"grasp": 0.05, "tap": 0.9, "touch": 0.05})
    assert max(fused.marginal("Action").items(), key=lambda kv: kv[1])[0] == "tap"
