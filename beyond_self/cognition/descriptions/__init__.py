"""Verbal descriptions: score the grammar's sentences by word probabilities and find the N best.

The entry points are `nbest_exact` (exact over all ~9.3M sentences), `nbest_from_file`,
`nbest_from_sentences`, `nbest_sampled`, `sample_sentences` (like HTK's HSGen), `score_sentence`
and the brute forces the benchmark compares with. A sentence of L words scores (1/L) Σ log P(w),
repeated words counted each time; `legacy_offset=True` scores (1 + Σ log P)/L, as the code behind
the article's tables did; `require` keeps sentences matching a regex. log P is rounded to a
multiple of 2**-32 so every route gives a sentence the same score to the last bit and equal words
tie exactly (input order, or lexicographic order for the exact search).
"""

from __future__ import annotations

from beyond_self.cognition.descriptions.plot import plot_nbest
from beyond_self.cognition.descriptions.sampling import (
    SAMPLES_MAX,
    hsgen_phrase_probabilities,
    sample_keys,
    sample_sentences,
)
from beyond_self.cognition.descriptions.search import (
    NBEST_MAX,
    Ranking,
    brute_force_nbest,
    brute_force_nbest_plain,
    brute_force_scores,
    nbest_exact,
    nbest_from_file,
    nbest_from_sentences,
    nbest_sampled,
    top_keys,
)
from beyond_self.cognition.descriptions.space import ScoredSentence, SentenceSpace, score_sentence

__all__ = [
    "NBEST_MAX",
    "SAMPLES_MAX",
    "Ranking",
    "ScoredSentence",
    "SentenceSpace",
    "brute_force_nbest",
    "brute_force_nbest_plain",
    "brute_force_scores",
    "hsgen_phrase_probabilities",
    "nbest_exact",
    "nbest_from_file",
    "nbest_from_sentences",
    "nbest_sampled",
    "plot_nbest",
    "sample_keys",
    "sample_sentences",
    "score_sentence",
    "top_keys",
]
