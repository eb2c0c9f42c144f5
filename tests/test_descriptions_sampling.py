"""Random sentences drawn like HTK's HSGen, checked against the article's own samples."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chisquare

from beyond_self.cognition.descriptions import (
    SentenceSpace,
    hsgen_phrase_probabilities,
    nbest_from_sentences,
    nbest_sampled,
    sample_keys,
    sample_sentences,
)
from beyond_self.cognition.grammar import DEFAULT_GRAMMAR, Phrase, parse_grammar
from beyond_self.core.errors import InputError

# By hand, from the walk over the word network (uniform among the words that can come next):
# after the agent, each of 6 verbs offers 5 next words {V-s, has, just, V-ed, is}; after "has",
# 2 {just, V-ed}. After "the": 10 {big, small, green, yellow, blue, 5 shapes}; after a size: 8.
_FORM = {"s": Fraction(1, 5), "ed": Fraction(1, 5), "just": Fraction(1, 5)}
_FORM |= {"has": Fraction(1, 10), "has just": Fraction(1, 10), "ing": Fraction(1, 5)}
_OBJECT = {  # (size?, colour?) -> probability of the modifier pattern
    (False, False): Fraction(5, 10),
    (False, True): Fraction(3, 10),
    (True, False): Fraction(2, 10) * Fraction(5, 8),
    (True, True): Fraction(2, 10) * Fraction(3, 8),
}


def _form(phrase: Phrase) -> str:
    if phrase[0] == "is":
        return "ing"
    if phrase[0] == "has":
        return "has just" if phrase[1] == "just" else "has"
    if phrase[0] == "just":
        return "just"
    return "ed" if phrase[0].endswith("ed") else "s"


def _modifiers(phrase: Phrase) -> tuple[bool, bool]:
    return (
        bool({"big", "small"} & set(phrase)),
        bool({"green", "yellow", "blue"} & set(phrase)),
    )


def test_walk_probabilities_match_the_hand_derivation() -> None:
    agent, action, obj, conj, obj2, effect = hsgen_phrase_probabilities()
    assert obj == pytest.approx(obj2)
    assert all(v == pytest.approx(1 / 3) for v in agent.values())
    assert all(v == pytest.approx(1 / 2) for v in conj.values())
    assert len(effect) == 12 and all(v == pytest.approx(1 / 12) for v in effect.values())
    for phrase, p in action.items():
        assert p == pytest.approx(float(_FORM[_form(phrase)] / 6)), phrase
    for phrase, p in obj.items():
        n_shapes, n_colours, n_sizes = 5, 3, 2
        pattern = _modifiers(phrase)
        share = n_shapes * (n_colours if pattern[1] else 1) * (n_sizes if pattern[0] else 1)
        assert p == pytest.approx(float(_OBJECT[pattern] / share)), phrase
    for dist in (agent, action, obj, conj, effect):
        assert sum(dist.values()) == pytest.approx(1.0)


def test_leaving_a_slot_counts_the_words_that_can_start_the_next() -> None:
    # after "x" the walk can go on to "y" or to either first word of slot b: x = 1/2 * 2/3
    g = parse_grammar("sentence = a b\na = x [y] | z\nb = w | v")
    a, b = hsgen_phrase_probabilities(g)
    assert a == pytest.approx({("x",): 1 / 3, ("x", "y"): 1 / 6, ("z",): 1 / 2})
    assert b == pytest.approx({("w",): 1 / 2, ("v",): 1 / 2})


def test_a_slot_that_can_be_empty_is_refused() -> None:
    with pytest.raises(InputError, match="can be empty"):
        sample_sentences(3, 0, grammar=parse_grammar("sentence = a b\na = [x]\nb = y"))


def test_sampler_is_seeded_and_follows_its_distribution() -> None:
    assert sample_sentences(50, 4) == sample_sentences(50, 4)
    assert sample_sentences(50, 4) != sample_sentences(50, 5)
    space = SentenceSpace.of()
    ranks = space.phrase_ranks(sample_keys(60_000, 123))
    for slot, probs in enumerate(hsgen_phrase_probabilities()):
        name = DEFAULT_GRAMMAR.slots[slot]
        expected = np.array([probs[p] for p in space.phrases[name]]) * 60_000
        observed = np.bincount(ranks[slot], minlength=expected.shape[0])
        assert chisquare(observed, expected).pvalue > 1e-3, name


def _features(lines: list[str]) -> dict[str, Counter[object]]:
    space = SentenceSpace.of()
    ranks = space.phrase_ranks(space.parse_lines(lines))
    phrases = [
        [space.phrases[name][r] for r in ranks[slot]]
        for slot, name in enumerate(DEFAULT_GRAMMAR.slots)
    ]
    return {
        "agent": Counter(phrases[0]),
        "form": Counter(map(_form, phrases[1])),
        "verb": Counter(p[-1][:4] for p in phrases[1]),
        "modifiers": Counter(map(_modifiers, phrases[2] + phrases[4])),
        "shape": Counter(p[-1] for p in phrases[2] + phrases[4]),
        "conjunction": Counter(phrases[3]),
        "effect": Counter(phrases[5]),
    }


def _model_features() -> dict[str, dict[object, float]]:
    agent, action, obj, conj, _, effect = hsgen_phrase_probabilities()

    def marginal(dist: dict[Phrase, float], f: Callable[[Phrase], object]) -> dict[object, float]:
        out: dict[object, float] = {}
        for phrase, p in dist.items():
            out[f(phrase)] = out.get(f(phrase), 0.0) + p
        return out

    return {
        "agent": dict(agent),
        "form": marginal(action, _form),
        "verb": marginal(action, lambda p: p[-1][:4]),
        "modifiers": marginal(obj, _modifiers),
        "shape": marginal(obj, lambda p: p[-1]),
        "conjunction": dict(conj),
        "effect": dict(effect),
    }


@pytest.mark.parametrize("name", ["sentence_1000samples.txt", "sentence_10000samples_uniq.txt"])
def test_the_articles_samples_fit_the_walk_and_reject_coin_flips(
    shared_data: Path, name: str
) -> None:
    lines = (shared_data / "saponaro2019" / name).read_text().splitlines()
    observed = _features(lines)
    for feature, expected in _model_features().items():
        keys = list(expected)
        counts = np.array([observed[feature][k] for k in keys], dtype=float)
        assert counts.sum() == (2 if feature in ("modifiers", "shape") else 1) * len(lines)
        probs = np.array([expected[k] for k in keys])
        assert chisquare(counts, probs * counts.sum()).pvalue > 1e-3, feature
    # the other reading of "uniform": 1/3 per alternative of "V-s | [has] [just] V-ed | is V-ing"
    # and a fair coin per [optional]; the article's samples rule it out
    coin = {"s": 1 / 3, "ing": 1 / 3} | dict.fromkeys(["ed", "just", "has", "has just"], 1 / 12)
    counts = np.array([observed["form"][k] for k in coin], dtype=float)
    assert chisquare(counts, np.array(list(coin.values())) * counts.sum()).pvalue < 1e-20
    coin_mod = np.array([observed["modifiers"][k] for k in _OBJECT], dtype=float)
    assert chisquare(coin_mod, np.full(4, coin_mod.sum() / 4)).pvalue < 1e-20


def test_sampled_nbest_is_the_nbest_of_the_unique_samples() -> None:
    rng = np.random.default_rng(9)
    probs = {
        w: float(p)
        for w, p in zip(DEFAULT_GRAMMAR.vocabulary, rng.uniform(0.05, 0.95, 49), strict=True)
    }
    drawn = sample_sentences(3000, 21)
    got = nbest_sampled(probs, 3000, 21, 15, require="but")
    assert got == nbest_from_sentences(drawn, probs, 15, require="but")
    assert all("but" in it.sentence for it in got)
    assert len({it.sentence for it in nbest_sampled(probs, 3000, 21, 3000)}) == len(set(drawn))
