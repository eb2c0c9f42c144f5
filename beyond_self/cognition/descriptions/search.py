"""N-best sentences: exact over the whole grammar, from a list of sentences, from random samples.

The exact search never enumerates the sentences. A sentence is a (prefix, suffix) pair of the
space's two blocks; among prefixes of one length a better sum gives a better sentence whatever
suffix follows, so the global N-best's prefixes are among the N best of their length, and the
same for suffixes. Those lists crossed (a few thousand pairs) are scored exactly and ranked by
(score, key); lengths then compete on sum/L. Exact sums and key-ordered ties keep it exact, not
nearly so. `require` asks for the exact top K, keeps the matches, and grows K fourfold until N
match or the grammar is exhausted.
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TypedDict, Unpack

import numpy as np

from beyond_self.cognition.descriptions.space import (
    FloatArray,
    IntArray,
    ScoredSentence,
    SentenceSpace,
    final_scores,
)
from beyond_self.cognition.grammar import DEFAULT_GRAMMAR, Grammar
from beyond_self.core.errors import InputError, read_text

Require = re.Pattern[str] | str | None


class Ranking(TypedDict, total=False):
    """The keyword options of the N-best searches, for a caller that passes them on as they are."""

    legacy_offset: bool
    require: Require
    grammar: Grammar


# A list longer than this is no description any more, and its work and memory grow with n
# (n = 10**12 reached 5 GB before failing): refused with the limit in the message.
NBEST_MAX = 10_000


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
    word_lp = space.word_logprobs(word_probs)
    if pattern is None:
        keys, scores = top_keys(space, word_lp, n, legacy_offset)
        return [
            ScoredSentence(space.sentence(k), float(x)) for k, x in zip(keys, scores, strict=True)
        ]
    found: list[ScoredSentence] = []
    done = 0
    k = max(64, 4 * n)
    while True:
        keys, scores = top_keys(space, word_lp, k, legacy_offset)
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
    word_lp: FloatArray,
    k: int,
    legacy_offset: bool = False,
    method: str = "auto",
) -> tuple[IntArray, FloatArray]:
    """Keys and scores of the exact top k sentences, best first (ties by key).

    `word_lp` comes from `space.word_logprobs`. `method`: "bounds" (the fast path, when it
    applies), "blocks" (always applies), or "auto" (bounds, else blocks); all give the same.
    """
    if method != "blocks":
        found = _top_keys_bounded(space, word_lp, k, legacy_offset)
        if found is not None or method == "bounds":
            if found is None:
                raise InputError("the bounded search does not apply to these probabilities")
            return found
    prefix_sums, suffix_sums = space.block_sums(word_lp)
    # Sentences scoring -inf (a word with P = 0) are all tied, so they rank by key alone and a
    # better prefix sum says nothing about them: the search ranks the finite ones, and any
    # places left go to the -inf sentences with the smallest keys.
    cp = _keep(space.prefix.by_length, space.prefix.bounds, prefix_sums, k)
    cs = _keep(space.suffix.by_length, space.suffix.bounds, suffix_sums, k)
    sums = prefix_sums[cp][:, None] + suffix_sums[cs][None, :]
    lengths = space.prefix.lengths[cp][:, None] + space.suffix.lengths[cs][None, :]
    scores = final_scores(sums, lengths, legacy_offset).ravel()
    keys = (cp[:, None] * space.suffix.size + cs[None, :]).ravel()
    order = _top_order(scores, keys, k)
    keys, scores = keys[order], scores[order]
    need = min(k, space.count) - keys.shape[0]
    if need > 0:
        more = _first_impossible_keys(space, prefix_sums, suffix_sums, need)
        keys = np.concatenate([keys, more])
        scores = np.concatenate([scores, np.full(more.shape[0], -np.inf)])
    return keys, scores


_ZERO = np.zeros(1)
_ZERO_KEY = np.zeros(1, dtype=np.int64)
_MINUS_INF = np.full(1, -np.inf)
# Above this many surviving sentences the bounded search hands over to the block search.
_BOUNDED_MAX = 8192


def _top_keys_bounded(
    space: SentenceSpace, word_lp: FloatArray, k: int, legacy_offset: bool
) -> tuple[IntArray, FloatArray] | None:
    """The exact top k by bounding first, when at least k sentences score above -inf.

    1. A lower bound tau on the k-th best score from k real sentences: for every choice of one
       length per position, the sentence of the best phrases and its one-phrase variants using
       a group's second best (all exact scores of distinct sentences).
    2. A sentence scores >= tau iff the sum over positions of w = log P - tau * length is >= 0
       (>= -1 with the legacy offset); with the best w of every other position, that bounds the
       w each phrase needs. Few phrases pass, and their cross product holds every sentence
       scoring >= tau, hence the top k: it is scored exactly and ranked by (score, key).
    Returns None (use the block search) when fewer than k finite candidates are known, a whole
    length group is impossible, or too many sentences survive (massive ties).
    """
    t = space.positions
    shift = 1.0 if legacy_offset else 0.0
    entry_lp = np.concatenate((word_lp, _ZERO))[t.table].sum(axis=1)  # exact, see `space`
    ranked = np.concatenate((entry_lp[np.lexsort((-entry_lp, t.group))], _MINUS_INF))
    best = ranked[t.group_starts]
    if np.isneginf(best).any():
        return None
    chosen = best[t.combos]
    top = chosen.sum(axis=1) + shift
    variants = (top[:, None] - chosen + ranked[t.second][t.combos]) / t.combo_length[:, None]
    candidates = np.concatenate((top / t.combo_length, variants.ravel()))
    m = candidates.shape[0]
    if k > m:
        return None
    tau = np.partition(candidates, m - k)[m - k]
    if not np.isfinite(tau):
        return None
    w = entry_lp - tau * t.length
    best_w = np.maximum.reduceat(w, t.position_starts)
    # generous slack for the rounding of w and of the scores compared with tau
    slack = 1e-9 * (1.0 + abs(tau) * float(t.combo_length.max()))
    keep = np.flatnonzero(w + (best_w.sum() + shift + slack) >= best_w[t.position])
    bounds = np.searchsorted(keep, t.position_bounds).tolist()
    counts = [b - a for a, b in itertools.pairwise(bounds)]
    if math.prod(counts) > _BOUNDED_MAX:
        return None
    kept_lp, kept_len, kept_key = entry_lp[keep], t.length[keep], t.key[keep]
    # single survivors are constants; the others span the axes of the cross product
    singles = [a for a, b in itertools.pairwise(bounds) if b - a == 1]
    const_lp = float(kept_lp[singles].sum()) + shift
    const_len = float(kept_len[singles].sum())
    const_key = int(kept_key[singles].sum())
    sums, lengths, keys = _ZERO, _ZERO, _ZERO_KEY
    for a, b in itertools.pairwise(bounds):
        if b - a > 1:
            sums = np.add.outer(sums, kept_lp[a:b])
            lengths = np.add.outer(lengths, kept_len[a:b])
            keys = np.add.outer(keys, kept_key[a:b])
    scores = ((sums + const_lp) / (lengths + const_len)).ravel()
    flat_keys = (keys + const_key).ravel()
    order = _top_order(scores, flat_keys, k)
    return flat_keys[order], scores[order]


def _first_impossible_keys(
    space: SentenceSpace, prefix_sums: FloatArray, suffix_sums: FloatArray, need: int
) -> IntArray:
    """The `need` smallest keys of sentences scoring -inf."""
    n_suffix = space.suffix.size
    bad_prefix = np.isneginf(prefix_sums)
    bad_suffix = np.flatnonzero(np.isneginf(suffix_sums))
    all_suffixes = np.arange(n_suffix)
    per_prefix = np.where(bad_prefix, n_suffix, bad_suffix.shape[0])
    stop = int(np.searchsorted(np.cumsum(per_prefix), need)) + 1
    parts = [
        p * n_suffix + (all_suffixes if bad_prefix[p] else bad_suffix)
        for p in range(min(stop, prefix_sums.shape[0]))
        if per_prefix[p]
    ]
    return np.concatenate([np.zeros(0, dtype=np.int64), *parts])[:need]


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
    """The N best by scoring every sentence (ties: lexicographic); the exact search's reference.

    As fast as plain numpy allows without using the exact search's insight: every sentence's
    score is computed, in cache-sized chunks of prefixes (each chunk against all suffixes),
    keeping only each prefix's best score; the k-th best of those bounds the k-th best sentence
    from below, and only the prefixes reaching it are scored again to pick the winners.
    """
    space = SentenceSpace.of(grammar)
    k = min(_check_n(n), space.count)
    prefix_sums, suffix_sums = space.block_sums(space.word_logprobs(word_probs))
    pre, suf = space.prefix, space.suffix
    p_sums, s_sums = prefix_sums[pre.by_length], suffix_sums[suf.by_length]
    p_len, s_len = pre.lengths[pre.by_length], suf.lengths[suf.by_length]
    shift = 1.0 if legacy_offset else 0.0
    row_best = np.empty(pre.size)
    buffer = np.empty((_BRUTE_ROWS, suf.size))
    for a, b in pre.bounds:  # prefixes of one length, so L is constant per suffix group
        for r0 in range(a, b, _BRUTE_ROWS):
            r1 = min(b, r0 + _BRUTE_ROWS)
            block = buffer[: r1 - r0]
            np.add.outer(p_sums[r0:r1], s_sums, out=block)
            if shift:
                block += shift
            for c0, c1 in suf.bounds:
                block[:, c0:c1] /= float(p_len[a] + s_len[c0])
            block.max(axis=1, out=row_best[r0:r1])
    cut = max(pre.size - k, 0)
    threshold = np.partition(row_best, cut)[cut] if k <= pre.size else -np.inf
    rows = np.flatnonzero(row_best >= threshold)
    sub = (np.add.outer(p_sums[rows], s_sums) + shift) / np.add.outer(p_len[rows], s_len)
    r, c = np.nonzero(sub >= threshold)
    keys = pre.by_length[rows[r]] * suf.size + suf.by_length[c]
    scores = sub[r, c]
    order = _top_order(scores, keys, k)
    return [ScoredSentence(space.sentence(int(keys[i])), float(scores[i])) for i in order]


_BRUTE_ROWS = 256  # prefixes per chunk: 256 x 1,440 scores = 2.9 MB, cache-sized


def brute_force_nbest_plain(
    word_probs: Mapping[str, float],
    n: int = 10,
    *,
    legacy_offset: bool = False,
    grammar: Grammar = DEFAULT_GRAMMAR,
) -> list[ScoredSentence]:
    """The textbook brute force: the full array of 9.3M scores, then a partial sort."""
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
    path: str | Path, word_probs: Mapping[str, float], n: int = 10, **ranking: Unpack[Ranking]
) -> list[ScoredSentence]:
    """`nbest_from_sentences` over a file of sentences, one per line (HSGen's output format)."""
    path = Path(path)
    text = read_text(path, "sentence file", missing="; give a file of sentences")
    if not text.strip():
        raise InputError(f"sentence file {path} is empty; valid: one sentence per line")
    return nbest_from_sentences(text.splitlines(), word_probs, n, source=str(path), **ranking)


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
    from beyond_self.cognition.descriptions.sampling import sample_keys

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


def _keep(
    by_length: IntArray, bounds: tuple[tuple[int, int], ...], sums: FloatArray, k: int
) -> IntArray:
    """Finite-sum block entries among the k best of their length group by (sum desc, key asc)."""
    ordered = sums[by_length]
    all_finite = not np.isneginf(ordered).any()
    kept: list[IntArray] = []
    for start, stop in bounds:
        keys = by_length[start:stop]  # ascending within a length, so ties come in key order
        values = ordered[start:stop]
        if not all_finite:
            finite = values > -np.inf
            keys, values = keys[finite], values[finite]
        if keys.shape[0] <= k:
            kept.append(keys)
            continue
        cut = keys.shape[0] - k
        part = np.argpartition(values, cut)
        v = values[part[cut]]  # the k-th best sum
        if np.count_nonzero(values == v) == 1:  # no tie at the cut: the partition is the answer
            kept.append(keys[part[cut:]])
            continue
        above = keys[values > v]
        kept.append(above)
        kept.append(keys[values == v][: k - above.shape[0]])
    return np.concatenate(kept)


def _top_order(scores: FloatArray, keys: IntArray | None, k: int) -> IntArray:
    """Positions of the k best by (score desc, key asc), in that order; keys None = position."""
    m = scores.shape[0]
    if m <= 512:  # small: one sort beats partitioning
        tiebreak = np.arange(m) if keys is None else keys
        return np.lexsort((tiebreak, -scores))[:k]
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


def _check_n(n: int) -> int:
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or not 1 <= n <= NBEST_MAX:
        raise InputError(f"N-best size must be a positive integer up to {NBEST_MAX}, got {n!r}")
    return int(n)


def _compile(require: Require) -> re.Pattern[str] | None:
    if require is None or isinstance(require, re.Pattern):
        return require
    try:
        return re.compile(require)
    except re.error as exc:
        raise InputError(f"invalid regular expression {require!r} for require: {exc}") from None
