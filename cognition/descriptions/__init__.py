"""Verbal descriptions: score the grammar's sentences by word probabilities and find the N best.

What other modules call (word_probs = {word: P(word present | evidence)} for every grammar word):

    nbest_exact(word_probs, n=10, *, legacy_offset=False, require=None, grammar=DEFAULT_GRAMMAR)
        -> list[ScoredSentence]        # exact N-best over all ~9.3M sentences, ~0.15 ms
    nbest_from_file(path, word_probs, n=10, **ranking)   # Ranking: legacy_offset, require, grammar
    nbest_from_sentences(lines, word_probs, n=10, *, legacy_offset, require, grammar, source)
    nbest_sampled(word_probs, samples, seed, n=10, *, legacy_offset, require, grammar)
    sample_sentences(count, seed, *, grammar) -> list[str]      # like HTK's HSGen -n count
    score_sentence(sentence, word_probs, *, legacy_offset=False) -> float
    brute_force_scores(word_probs, *, legacy_offset, grammar) -> ndarray   # every sentence
    brute_force_nbest(word_probs, n=10, *, legacy_offset, grammar)     # chunked, fastest
    brute_force_nbest_plain(word_probs, n=10, *, legacy_offset, grammar)  # full array + sort
    plot_nbest(items, path, title) -> Path                        # PNG bar chart
    hsgen_phrase_probabilities(grammar) -> [{phrase: P}] per slot  # the sampler's distribution
    SentenceSpace.of(grammar); top_keys(space, space.word_logprobs(p), k, legacy, method)

A sentence of L words scores (1/L) Σ log P(w_k), repeated words counted each time; a word with
P = 0 makes it −inf. `legacy_offset=True` scores (1 + Σ log P)/L, as the reference code that
produced the article's tables did. `require` keeps only sentences matching a regex (re.search).
Ties: input order for given or sampled sentences, lexicographic sentence order for exact search.
log P is rounded to a multiple of 2**-32 (< 1.2e-10) so sums are exact: every route gives a
sentence the same score to the last bit, and sentences with the same words tie exactly.
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
