"""N-best sentences: exact over the whole grammar, from a list of sentences, from random samples.

The exact search never enumerates the ~9.3 million sentences. A sentence is a (prefix, suffix)
pair of the space's two blocks and scores (Σ log P)/L with L = prefix length + suffix length. Among
prefixes of the same length, a better sum gives a better sentence whatever suffix follows (same L),
so a sentence of the global N-best has a prefix among the N best of its length group, and a suffix
among the N best of its own; the candidates are those lists crossed (a few thousand pairs), scored
exactly as the brute force scores them, and ranked by (score, key). Search over length is that
grouping: every total length gets its best sums from the per-length lists, then lengths compete on
sum/L.

Two details keep it exact rather than nearly so:
- ties: a prefix group keeps the N best by (sum, key); equal sums stay equal after the same suffix
  is added, and the key order of prefixes is the key order of the sentences they start;
- rounding: sums are exact (see `space`), but two different sums closer than a few ulp could
  still round to the same score when divided by L, and then the key decides; a group with such a
  near-tie at its cut keeps everything within that margin (it takes log-probabilities in the
  hundreds to happen at all, since exact sums differ by at least 2**-32).

`require` (a regex the sentence must match) is handled by asking for the exact top K, keeping the
matches, and growing K fourfold until N matches are found or the grammar is exhausted: the top K
is exact, so its first N matches are the N best matching sentences.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np

from cognition.descriptions.space import (
    FloatArray,
    IntArray,
    ScoredSentence,
    SentenceSpace,
    final_scores,
)
from cognition.errors import InputError
from cognition.grammar import DEFAULT_GRAMMAR, Grammar

Require = re.Pattern[str] | str | None


def nbest_exact(
    word_probs: Mapping[str, float],
    n: int = 10,
    *,
    legacy_offset: bool = False,
    require: Require = None,
    grammar: Grammar = DEFAULT_GRAMMAR,
) -> list[ScoredSentence]:
    """The N best sentences of the whole grammar (ties: lexicographic), without enumerating it."""
    space = SentenceSpace.of(grammar)
    n = _check_n(n)
    pattern = _compile(require)
    prefix_sums, suffix_sums = space.block_sums(space.word_logprobs(word_probs))
    if pattern is None:
        keys, scores = top_keys(space, prefix_sums, suffix_sums, n, legacy_offset)
        return [
            ScoredSentence(space.sentence(k), float(x)) for k, x in zip(keys, scores, strict=True)
        ]
    found: list[ScoredSentence] = []
    done = 0
    k = max(64, 4 * n)
    while True:
        keys, scores = top_keys(space, prefix_sums, suffix_sums, k, legacy_offset)
        for key, score in zip(keys[done:], scores[done:], strict=True):
            sentence = space.sentence(int(key))
            if pattern.search(sentence):
                found.append(ScoredSentence(sentence, float(score)))
                if len(found) == n:
                    return found
        done = len(keys)
        if k >= space.count:
            return found
        k = min(4 * k, space.count)


def top_keys(
    space: SentenceSpace,
    prefix_sums: FloatArray,
    suffix_sums: FloatArray,
    k: int,
    legacy_offset: bool = False,
) -> tuple[IntArray, FloatArray]:
    """Keys and scores of the exact top k sentences, best first (ties by key)."""
    margin = _margin(prefix_sums, suffix_sums)
    cp = np.concatenate([_keep(prefix_sums, g, k, margin) for g in space.prefix.groups])
    cs = np.concatenate([_keep(suffix_sums, g, k, margin) for g in space.suffix.groups])
    sums = prefix_sums[cp][:, None] + suffix_sums[cs][None, :]
    lengths = space.prefix.lengths[cp][:, None] + space.suffix.lengths[cs][None, :]
    scores = final_scores(sums, lengths, legacy_offset).ravel()
    keys = (cp[:, None] * space.suffix.size + cs[None, :]).ravel()
    order = _top_order(scores, keys, k)
    return keys[order], scores[order]


def brute_force_scores(
    word_probs: Mapping[str, float],
    *,
    legacy_offset: bool = False,
    grammar: Grammar = DEFAULT_GRAMMAR,
) -> FloatArray:
    """The score of every sentence of the grammar, indexed by key (lexicographic order).

    The reference the exact search is checked against: one vectorised pass over all sentences.
    """
    space = SentenceSpace.of(grammar)
    prefix_sums, suffix_sums = space.block_sums(space.word_logprobs(word_probs))
    scores = np.add.outer(prefix_sums, suffix_sums).ravel()
    if legacy_offset:
        scores += 1.0
    np.divide(scores, space.sentence_lengths, out=scores)
    return scores


def brute_force_nbest(
    word_probs: Mapping[str, float],
    n: int = 10,
    *,
    legacy_offset: bool = False,
    grammar: Grammar = DEFAULT_GRAMMAR,
) -> list[ScoredSentence]:
    """The N best by scoring every sentence (ties: lexicographic); the exact search's reference."""
    space = SentenceSpace.of(grammar)
    scores = brute_force_scores(word_probs, legacy_offset=legacy_offset, grammar=grammar)
    order = _top_order(scores, None, _check_n(n))
    return [ScoredSentence(space.sentence(int(k)), float(scores[k])) for k in order]


def nbest_from_sentences(
    sentences: Iterable[str],
    word_probs: Mapping[str, float],
    n: int = 10,
    *,
    legacy_offset: bool = False,
    require: Require = None,
    grammar: Grammar = DEFAULT_GRAMMAR,
    source: str = "sentences",
) -> list[ScoredSentence]:
    """The N best of given sentences (one per item, blank ones skipped, repeats counted once).

    Ties keep the order of the input. Every sentence must be derivable by the grammar; the first
    that is not (or that has an unknown word) is an InputError naming its line in `source`.
    """
    space = SentenceSpace.of(grammar)
    keys = space.parse_lines(sentences, source)
    return _rank_keys(space, keys, word_probs, _check_n(n), legacy_offset, _compile(require))


def nbest_from_file(
    path: str | Path,
    word_probs: Mapping[str, float],
    n: int = 10,
    *,
    legacy_offset: bool = False,
    require: Require = None,
    grammar: Grammar = DEFAULT_GRAMMAR,
) -> list[ScoredSentence]:
    """`nbest_from_sentences` over a file of sentences, one per line (HSGen's output format)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"sentence file {path} does not exist; give a file of sentences") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read sentence file {path}: {exc}") from None
    return nbest_from_sentences(
        text.splitlines(),
        word_probs,
        n,
        legacy_offset=legacy_offset,
        require=require,
        grammar=grammar,
        source=str(path),
    )


def nbest_sampled(
    word_probs: Mapping[str, float],
    samples: int,
    seed: int,
    n: int = 10,
    *,
    legacy_offset: bool = False,
    require: Require = None,
    grammar: Grammar = DEFAULT_GRAMMAR,
) -> list[ScoredSentence]:
    """The article's method: draw `samples` sentences like HSGen, drop repeats, re-score, rank.

    Ties keep the order in which the sentences were first drawn.
    """
    from cognition.descriptions.sampling import sample_keys

    space = SentenceSpace.of(grammar)
    keys = sample_keys(samples, seed, grammar=grammar)
    return _rank_keys(space, keys, word_probs, _check_n(n), legacy_offset, _compile(require))


def _rank_keys(
    space: SentenceSpace,
    keys: IntArray,
    word_probs: Mapping[str, float],
    n: int,
    legacy_offset: bool,
    pattern: re.Pattern[str] | None,
) -> list[ScoredSentence]:
    """Rank sentence keys given in order: repeats dropped, ties by first position."""
    _, first = np.unique(keys, return_index=True)
    keys = keys[np.sort(first)]
    prefix_sums, suffix_sums = space.block_sums(space.word_logprobs(word_probs))
    p, s = space.split_keys(keys)
    sums = prefix_sums[p] + suffix_sums[s]
    scores = final_scores(sums, space.prefix.lengths[p] + space.suffix.lengths[s], legacy_offset)
    order = np.argsort(-scores, kind="stable")
    out: list[ScoredSentence] = []
    for i in order:
        sentence = space.sentence(int(keys[i]))
        if pattern is None or pattern.search(sentence):
            out.append(ScoredSentence(sentence, float(scores[i])))
            if len(out) == n:
                break
    return out


def _keep(sums: FloatArray, group: IntArray, k: int, margin: float) -> IntArray:
    """Entries of a length group that can start (or end) a top-k sentence."""
    if group.shape[0] <= k:
        return group
    values = sums[group]
    v = values[np.argpartition(-values, k - 1)[k - 1]]  # the k-th best sum
    if np.isfinite(v):
        near = (values != v) & (values >= v - margin) & (values <= v + margin)
        if near.any():  # rounding could merge these later: keep all that might
            return group[values >= v - margin]
    above = group[values > v]
    ties = group[values == v]  # group is ascending, so ties are in key order
    return np.concatenate([above, ties[: k - above.shape[0]]])


def _top_order(scores: FloatArray, keys: IntArray | None, k: int) -> IntArray:
    """Positions of the k best by (score desc, key asc), in that order; keys None = position."""
    m = scores.shape[0]
    if m > k:
        v = scores[np.argpartition(scores, m - k)[m - k]]  # the k-th largest score
        above = np.flatnonzero(scores > v)
        ties = np.flatnonzero(scores == v)
        if keys is not None:
            ties = ties[np.argsort(keys[ties], kind="stable")]
        sel = np.concatenate([above, ties[: k - above.shape[0]]])
    else:
        sel = np.arange(m)
    tiebreak = sel if keys is None else keys[sel]
    return sel[np.lexsort((tiebreak, -scores[sel]))]


def _margin(prefix_sums: FloatArray, suffix_sums: FloatArray) -> float:
    """A bound, with room to spare, on what rounding can take off the gap between two sums."""
    finite = [np.abs(a[np.isfinite(a)]).max(initial=0.0) for a in (prefix_sums, suffix_sums)]
    return float(64 * np.finfo(np.float64).eps * (finite[0] + finite[1] + 2.0))


def _check_n(n: int) -> int:
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise InputError(f"N-best size must be a positive integer, got {n!r}")
    return int(n)


def _compile(require: Require) -> re.Pattern[str] | None:
    if require is None or isinstance(require, re.Pattern):
        return require
    try:
        return re.compile(require)
    except re.error as exc:
        raise InputError(f"invalid regular expression {require!r} for require: {exc}") from None
