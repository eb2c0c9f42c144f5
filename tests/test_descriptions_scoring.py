"""Sentence scores, N-best from a file of sentences, and the N-best plot."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from beyond_self.cognition.descriptions import (
    ScoredSentence,
    nbest_exact,
    nbest_from_file,
    nbest_from_sentences,
    plot_nbest,
    score_sentence,
)
from beyond_self.cognition.grammar import DEFAULT_GRAMMAR
from beyond_self.core.errors import InputError

# these figures are computed again under a second OpenBLAS kernel (Makefile: numeric)
pytestmark = pytest.mark.numeric


def _probs(seed: int) -> dict[str, float]:
    rng = np.random.default_rng(seed)
    return {
        w: float(p)
        for w, p in zip(DEFAULT_GRAMMAR.vocabulary, rng.uniform(0.05, 0.95, 49), strict=True)
    }


def test_score_is_the_mean_log_probability_with_repeats_counted() -> None:
    probs = dict.fromkeys(DEFAULT_GRAMMAR.vocabulary, 0.5)
    probs.update({"he": 0.9, "taps": 0.2, "ball": 0.7, "and": 0.6, "rolls": 0.4})
    sentence = "he taps the ball and the ball rolls"
    by_hand = (
        math.log(0.9) + math.log(0.2) + 2 * math.log(0.5) + 2 * math.log(0.7) + math.log(0.6)
    ) + math.log(0.4)
    assert score_sentence(sentence, probs) == pytest.approx(by_hand / 8, abs=1e-9)
    assert score_sentence(sentence, probs, legacy_offset=True) == pytest.approx(
        (1 + by_hand) / 8, abs=1e-9
    )
    # the same number from every route through the grammar
    listed = nbest_from_sentences([sentence], probs, 1)
    assert listed == [ScoredSentence(sentence, score_sentence(sentence, probs))]


def test_a_zero_probability_word_scores_minus_inf_quietly() -> None:
    probs = _probs(1) | {"rolls": 0.0}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert score_sentence("he taps the ball and the ball rolls", probs) == -math.inf
        got = nbest_from_sentences(
            ["he taps the ball and the ball rolls", "he taps the ball and the ball moves"],
            probs,
            5,
        )
    assert [it.sentence.split()[-1] for it in got] == ["moves", "rolls"]
    assert got[1].score == -math.inf


def test_file_order_breaks_ties_and_repeats_count_once(tmp_path: Path) -> None:
    probs = _probs(2) | {"sphere": 0.3, "ball": 0.3}
    lines = [
        "the robot pokes the sphere but the box is still",
        "",
        "the robot pokes the ball but the box is still",
        "the robot pokes the sphere but the box is still  ",
        "he is poking the big ball and the ball rolls",
    ]
    path = tmp_path / "s.txt"
    path.write_text("\n".join(lines) + "\n")
    got = nbest_from_file(path, probs, 10)
    assert len(got) == 3
    tied = [it for it in got if "pokes" in it.sentence]
    assert tied[0].score == tied[1].score
    assert [it.sentence for it in tied] == [lines[0], lines[2]]  # file order, not alphabetical
    only_big = nbest_from_file(path, probs, 10, require=r"\bbig\b")
    assert [it.sentence for it in only_big] == [lines[4]]


def test_bad_sentence_files_name_the_line(tmp_path: Path) -> None:
    probs = _probs(3)
    path = tmp_path / "bad.txt"
    good, bad = "he taps the ball and the ball rolls", "he taps the banana and the ball rolls"
    path.write_text(f"{good}\n\n{bad}\n")
    with pytest.raises(InputError, match=r"line 3: unknown word 'banana'.*valid words: the"):
        nbest_from_file(path, probs)
    path.write_text("he taps the ball and the ball rolls\nhe taps the ball the ball rolls\n")
    with pytest.raises(InputError, match=r"line 2: .* is not a sentence of the grammar"):
        nbest_from_file(path, probs)
    with pytest.raises(InputError, match="does not exist"):
        nbest_from_file(tmp_path / "absent.txt", probs)


def test_the_articles_sentence_list_reranked(shared_data: Path) -> None:
    path = shared_data / "saponaro2019" / "sentence_10000samples_uniq.txt"
    probs = _probs(4)
    got = nbest_from_file(path, probs, 10, legacy_offset=True)
    # independent re-scoring of every line, word by word, ties by line order
    lines = [" ".join(line.split()) for line in path.read_text().splitlines()]
    assert len(lines) == 9941
    rescored = sorted(
        ((1 + sum(math.log(probs[w]) for w in s.split())) / len(s.split()), -i, s)
        for i, s in enumerate(lines)
    )[::-1][:10]
    assert [it.sentence for it in got] == [s for _, _, s in rescored]
    assert [it.score for it in got] == pytest.approx([x for x, _, _ in rescored], abs=1e-9)
    # the whole grammar can only do better than a sample of it
    assert nbest_exact(probs, 1, legacy_offset=True)[0].score >= got[0].score


def test_plot_writes_a_png_even_with_minus_inf(tmp_path: Path) -> None:
    items = [
        ScoredSentence("he taps the ball and the ball rolls", -0.41),
        ScoredSentence("he taps the box and the ball rolls", -0.52),
        ScoredSentence("he taps the box and the box rolls", -math.inf),
    ]
    out = plot_nbest(items, tmp_path / "sub" / "nbest.png", "10-best")
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000
    with pytest.raises(InputError, match="empty"):
        plot_nbest([], tmp_path / "x.png", "none")
