"""The exact N-best search against references that enumerate every sentence.

Two references: a pure-Python one over a small grammar (every sentence as a string, scored word
by word, sorted by (-score, string): shares no code with the search), and the vectorised brute
force over the article's whole grammar (9,331,200 sentences).
"""

from __future__ import annotations

import itertools
import math
import re
import warnings
from collections.abc import Mapping

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from beyond_self.cognition.descriptions import (
    ScoredSentence,
    SentenceSpace,
    brute_force_nbest,
    brute_force_nbest_plain,
    brute_force_scores,
    nbest_exact,
    nbest_sampled,
    top_keys,
)
from beyond_self.cognition.grammar import DEFAULT_GRAMMAR, Grammar, parse_grammar
from beyond_self.core.errors import InputError

SMALL = parse_grammar(
    "\n".join(
        [
            "sentence = agent verb obj conj obj",
            "agent = the robot | he",
            "verb = pokes | [has] [just] poked | is poking",
            "obj = the [big | small] [red] shape",
            "shape = ball | box",
            "conj = and | but",
        ]
    )
)


def _qlog(p: float) -> float:
    """log p rounded to 2**-32, the documented scoring unit (-inf for 0)."""
    return -math.inf if p == 0 else round(math.log(p) * 2**32) / 2**32


def _reference(
    grammar: Grammar,
    probs: Mapping[str, float],
    n: int,
    legacy: bool = False,
    require: str | None = None,
) -> list[tuple[str, float]]:
    rows = []
    for phrases in grammar.sentences():
        words = [w for phrase in phrases for w in phrase]
        sentence = " ".join(words)
        if require is not None and not re.search(require, sentence):
            continue
        total = sum(_qlog(probs[w]) for w in words)
        rows.append((sentence, ((1.0 if legacy else 0.0) + total) / len(words)))
    rows.sort(key=lambda r: (-r[1], r[0]))
    return rows[:n]


def _pairs(items: list[ScoredSentence]) -> list[tuple[str, float]]:
    return [(it.sentence, it.score) for it in items]


def _random_probs(seed: int, grammar: Grammar = DEFAULT_GRAMMAR) -> dict[str, float]:
    rng = np.random.default_rng(seed)
    return {
        w: float(p) for w, p in zip(grammar.vocabulary, rng.uniform(0.02, 0.98, 100), strict=False)
    }


# -- small grammar, many random cases, independent reference -------------------------------------

_PROB_CHOICES = st.sampled_from([0.0, 0.1, 0.25, 0.5, 0.9, 1.0]) | st.floats(0.0, 1.0)


@settings(max_examples=60, deadline=None)
@given(
    probs=st.lists(_PROB_CHOICES, min_size=len(SMALL.vocabulary), max_size=len(SMALL.vocabulary)),
    n=st.integers(1, 40),
    legacy=st.booleans(),
)
def test_exact_equals_enumeration_on_a_small_grammar(
    probs: list[float], n: int, legacy: bool
) -> None:
    word_probs = dict(zip(SMALL.vocabulary, probs, strict=True))
    expected = _reference(SMALL, word_probs, n, legacy)
    got = nbest_exact(word_probs, n, legacy_offset=legacy, grammar=SMALL)  # bounds, else blocks
    assert _pairs(got) == expected
    space = SentenceSpace.of(SMALL)
    keys, scores = top_keys(space, space.word_logprobs(word_probs), n, legacy, method="blocks")
    assert [space.sentence(k) for k in keys] == [s for s, _ in expected]
    assert scores.tolist() == [x for _, x in expected]


@settings(max_examples=25, deadline=None)
@given(
    probs=st.lists(_PROB_CHOICES, min_size=len(SMALL.vocabulary), max_size=len(SMALL.vocabulary)),
    n=st.integers(1, 30),
    require=st.sampled_from([r"\bred\b", r"small red box and", r"^he .* but the big", "zzz"]),
)
def test_require_stays_exact(probs: list[float], n: int, require: str) -> None:
    word_probs = dict(zip(SMALL.vocabulary, probs, strict=True))
    got = nbest_exact(word_probs, n, require=require, grammar=SMALL)
    assert _pairs(got) == _reference(SMALL, word_probs, n, require=require)


def test_small_grammar_keys_are_lexicographic_order() -> None:
    space = SentenceSpace.of(SMALL)
    sentences = [space.sentence(k) for k in range(space.count)]
    assert sentences == sorted(" ".join(w for p in s for w in p) for s in SMALL.sentences())


# -- the article's grammar, against the vectorised brute force ----------------------------------


def test_exact_equals_brute_force_on_the_full_grammar() -> None:
    probs = _random_probs(7)
    for legacy in (False, True):
        brute = brute_force_nbest(probs, 25, legacy_offset=legacy)
        assert nbest_exact(probs, 25, legacy_offset=legacy) == brute
    # and the brute force itself agrees with word-by-word scoring on sampled sentences
    scores = brute_force_scores(probs)
    assert scores.shape == (3 * 36 * 60 * 2 * 60 * 12,)
    space = SentenceSpace.of()
    for key in np.random.default_rng(1).integers(0, scores.shape[0], 200):
        words = space.sentence(int(key)).split()
        assert scores[key] == sum(_qlog(probs[w]) for w in words) / len(words)


def test_both_search_methods_and_both_brute_forces_agree() -> None:
    space = SentenceSpace.of()
    for seed in range(3):
        word_lp = space.word_logprobs(_random_probs(seed))
        for legacy in (False, True):
            # "bounds" raises if it does not apply: random probabilities must take the fast path
            kb, sb = top_keys(space, word_lp, 15, legacy, method="bounds")
            kk, sk = top_keys(space, word_lp, 15, legacy, method="blocks")
            assert kb.tolist() == kk.tolist() and sb.tolist() == sk.tolist()
    probs = _random_probs(5) | {"he": 0.0, "ball": 0.0}
    probs["cube"] = probs["box"]
    for legacy in (False, True):
        chunked = brute_force_nbest(probs, 30, legacy_offset=legacy)
        assert chunked == brute_force_nbest_plain(probs, 30, legacy_offset=legacy)


def test_full_grammar_with_ties_zeros_and_a_colour_requirement() -> None:
    probs = _random_probs(11)
    # synonyms with identical probabilities, and impossible words
    probs["ball"] = probs["sphere"]
    probs["cube"] = probs["box"] = probs["square"]
    probs["baltazar"] = probs["he"] = 0.0
    probs["rolls"] = 1.0
    scores = brute_force_scores(probs)
    space = SentenceSpace.of()
    colours = {"green", "yellow", "blue"}
    # brute-force reference with a mask built from the phrases, not from the regex
    ranks = space.phrase_ranks(np.arange(scores.shape[0]))
    has_colour = np.zeros(scores.shape[0], dtype=bool)
    for slot in (2, 4):
        phrase_has = np.array([bool(colours & set(p)) for p in space.phrases["object"]])
        has_colour |= phrase_has[ranks[slot]]
    masked = np.where(has_colour, scores, -np.inf)
    top = np.lexsort((np.arange(masked.shape[0]), -masked))[:30]
    expected = [(space.sentence(int(k)), float(masked[k])) for k in top]
    got = nbest_exact(probs, 30, require=r"\b(green|yellow|blue)\b")
    assert _pairs(got) == expected
    assert all(math.isfinite(s) for _, s in expected)
    # plain ties: both orders of equal-score sentences come lexicographically
    plain = nbest_exact(probs, 40)
    assert plain == brute_force_nbest(probs, 40)
    tied = [(a, b) for a, b in itertools.pairwise(plain) if a.score == b.score]
    assert tied and all(a.sentence < b.sentence for a, b in tied)


def test_all_zero_probabilities_give_minus_inf_lexicographically_without_warnings() -> None:
    probs = dict.fromkeys(DEFAULT_GRAMMAR.vocabulary, 0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = nbest_exact(probs, 5)
    assert all(it.score == -math.inf for it in got)
    assert [it.sentence for it in got] == sorted(it.sentence for it in got)
    assert got[0].sentence == "baltazar grasped the ball and the ball falls"


def test_few_possible_sentences_come_first_then_impossible_ones_by_alphabet() -> None:
    probs = dict.fromkeys(DEFAULT_GRAMMAR.vocabulary, 0.0)
    probs |= dict.fromkeys(["the", "robot", "pokes", "ball", "box", "and", "moves"], 0.6)
    probs["box"] = 0.3
    got = nbest_exact(probs, 12)
    assert got == brute_force_nbest(probs, 12)
    finite = [it.sentence for it in got if math.isfinite(it.score)]
    assert finite == [
        "the robot pokes the ball and the ball moves",
        "the robot pokes the ball and the box moves",
        "the robot pokes the box and the ball moves",
        "the robot pokes the box and the box moves",
    ]
    assert [it.sentence for it in got[4:6]] == [
        "baltazar grasped the ball and the ball falls",
        "baltazar grasped the ball and the ball is falling",
    ]


def test_equal_probabilities_tie_everything_and_the_alphabet_decides() -> None:
    # all words P = 0.5: every sentence scores log 0.5 exactly, so the order is alphabetical
    got = nbest_exact(dict.fromkeys(DEFAULT_GRAMMAR.vocabulary, 0.5), 3)
    assert {it.score for it in got} == {_qlog(0.5)}
    assert [it.sentence for it in got] == [
        "baltazar grasped the ball and the ball falls",
        "baltazar grasped the ball and the ball is falling",
        "baltazar grasped the ball and the ball is inert",
    ]


def test_exact_best_is_never_worse_than_sampling() -> None:
    probs = _random_probs(3)
    best = nbest_exact(probs, 1)[0]
    sampled = nbest_sampled(probs, 2000, seed=5, n=1)[0]
    assert best.score >= sampled.score


def test_bad_arguments_are_input_errors() -> None:
    probs = _random_probs(0)
    with pytest.raises(InputError, match="positive integer"):
        nbest_exact(probs, 0)
    with pytest.raises(InputError, match="invalid regular expression"):
        nbest_exact(probs, 3, require="(unclosed")
    del probs["rolls"]
    with pytest.raises(InputError, match=r"'rolls'.*baltazar"):
        nbest_exact(probs)
    with pytest.raises(InputError, match=r"'he' is 1\.5"):
        nbest_exact({**_random_probs(0), "he": 1.5})
