"""A grammar's sentences compiled for scoring: phrase tables, two blocks of slots, sentence keys.

Every sentence is one phrase per slot, chosen independently; splitting the slots into a prefix
and a suffix block (6,480 prefixes and 1,440 suffixes for the article's grammar) keeps every table
small. Log-probabilities are rounded to multiples of 2**-32 so every sum is exact: a score does
not depend on the order its words are added in, and the exact search, the brute force and
`score_sentence` agree to the bit. Phrases are sorted and blocks enumerated in row-major order, so
a sentence's key `prefix_index * n_suffixes + suffix_index` is its lexicographic rank (exactly the
strings' order when no phrase of a slot is a word-prefix of another: `lexicographic_keys`).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from beyond_self.cognition.grammar import DEFAULT_GRAMMAR, Grammar, Phrase
from beyond_self.core.errors import InputError

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

# Probabilities a hair above 1 come out of normalisations in floating point; anything further is
# a caller's bug.
_PROB_SLACK = 1e-9
# log P rounded to this many fractional bits. |log P| <= 745 for any positive double, so a sum of
# up to MAX_WORDS of them needs at most 19 + 32 bits and is exact. Two different sums then differ
# by at least 2**-32, and divided by the same L <= MAX_WORDS by more than 2**-41, which is more
# than the rounding of a score (|score| <= 746, ulp <= 2**-43) can hide: a better sum always
# gives a strictly better score, the fact the exact search's pruning rests on.
LOG_FRACTION_BITS = 32
MAX_WORDS = 500
_SCALE = float(2**LOG_FRACTION_BITS)


class ScoredSentence(NamedTuple):
    """One entry of an N-best list; `score` is unrounded (the CLI rounds for display)."""

    sentence: str
    score: float


@dataclass(frozen=True)
class _Block:
    """Consecutive slots enumerated in row-major order (the last slot varies fastest)."""

    slots: tuple[int, ...]  # positions in the sentence
    sizes: tuple[int, ...]
    lengths: IntArray  # words per block entry
    by_length: IntArray  # entry indices ordered by length, then index (a stable sort)
    bounds: tuple[tuple[int, int], ...]  # [start, stop) in `by_length` of each distinct length

    @property
    def size(self) -> int:
        return int(self.lengths.shape[0])


@dataclass(frozen=True)
class Positions:
    """The phrases of each sentence position (a slot used twice appears twice), as flat arrays
    ordered by (position, length, rank); what the bound-pruned search works on."""

    table: IntArray  # word indices per entry, padded with len(vocabulary)
    length: FloatArray
    key: IntArray  # rank * (number of sentences per step of this position's rank)
    position: IntArray
    group: IntArray  # (position, length) group of each entry
    group_starts: IntArray
    second: IntArray  # per group, index of its second entry (or one past the end if none)
    position_starts: IntArray
    position_bounds: tuple[int, ...]  # starts plus the end
    combos: IntArray  # every choice of one length group per position: (combos, positions)
    combo_length: FloatArray

    @staticmethod
    def build(space: SentenceSpace) -> Positions:
        slots = space.grammar.slots
        pad = len(space.vocabulary)
        width = space._table.shape[1]
        sizes = [len(space.phrases[name]) for name in slots]
        table: list[list[int]] = []
        length: list[int] = []
        key: list[int] = []
        position: list[int] = []
        group: list[int] = []
        group_starts: list[int] = []
        group_length: list[int] = []
        position_starts: list[int] = []
        groups_of: list[list[int]] = []
        for j, name in enumerate(slots):
            position_starts.append(len(table))
            groups_of.append([])
            step = math.prod(sizes[j + 1 :])
            phrases = space.phrases[name]
            for n in sorted({len(p) for p in phrases}):
                groups_of[j].append(len(group_starts))
                group_starts.append(len(table))
                group_length.append(n)
                for rank, phrase in enumerate(phrases):
                    if len(phrase) == n:
                        idx = [space._word_index[w] for w in phrase]
                        table.append(idx + [pad] * (width - len(idx)))
                        length.append(n)
                        key.append(rank * step)
                        position.append(j)
                        group.append(len(group_starts) - 1)
        total = len(table)
        starts = np.array(group_starts, dtype=np.int64)
        group_sizes = np.diff(np.append(starts, total))
        combos = np.array(list(itertools.product(*groups_of)), dtype=np.int64)
        return Positions(
            table=np.array(table, dtype=np.int64).reshape(total, width),
            length=np.array(length, dtype=np.float64),
            key=np.array(key, dtype=np.int64),
            position=np.array(position, dtype=np.int64),
            group=np.array(group, dtype=np.int64),
            group_starts=starts,
            second=np.where(group_sizes >= 2, starts + 1, total),
            position_starts=np.array(position_starts, dtype=np.int64),
            position_bounds=(*position_starts, total),
            combos=combos,
            combo_length=np.array(group_length, dtype=np.float64)[combos].sum(axis=1),
        )


class SentenceSpace:
    """Everything about a grammar that does not depend on the word probabilities."""

    def __init__(self, grammar: Grammar) -> None:
        self.grammar = grammar
        self.vocabulary: tuple[str, ...] = grammar.vocabulary
        self._word_index = {w: i for i, w in enumerate(self.vocabulary)}
        names = tuple(dict.fromkeys(grammar.slots))
        self.slot_names = names
        # phrases of each distinct slot name, sorted by their words (the lexicographic ranks)
        self.phrases: dict[str, tuple[Phrase, ...]] = {
            name: tuple(sorted(grammar.phrases[name])) for name in names
        }
        for name in names:
            if not self.phrases[name]:
                raise InputError(f"grammar slot {name!r} has no phrases; every slot needs one")
        self.phrase_strings = {
            name: tuple(" ".join(p) for p in self.phrases[name]) for name in names
        }
        self.lexicographic_keys = all(
            not _has_word_prefix_pair(self.phrases[name]) for name in names
        )
        # one padded table of word indices for every phrase of every distinct slot; the pad
        # index points one past the vocabulary, where the log-probability table holds 0.0
        width = max(1, max(len(p) for name in names for p in self.phrases[name]))
        pad = len(self.vocabulary)
        rows: list[list[int]] = []
        self._slices: dict[str, slice] = {}
        for name in names:
            start = len(rows)
            for phrase in self.phrases[name]:
                idx = [self._word_index[w] for w in phrase]
                rows.append(idx + [pad] * (width - len(idx)))
            self._slices[name] = slice(start, len(rows))
        self._table = np.asarray(rows, dtype=np.int64).reshape(len(rows), width)
        self._phrase_lengths = {
            name: np.array([len(p) for p in self.phrases[name]], dtype=np.int64) for name in names
        }
        split = _best_split([len(self.phrases[s]) for s in grammar.slots])
        self.prefix = self._block(tuple(range(split)))
        self.suffix = self._block(tuple(range(split, len(grammar.slots))))
        self.count = self.prefix.size * self.suffix.size
        if self.count >= 2**62:
            raise InputError(f"grammar has {self.count} sentences; at most 2**62 are supported")
        if int(self.prefix.lengths.min()) + int(self.suffix.lengths.min()) == 0:
            raise InputError("grammar derives the empty sentence, which has no score")
        if int(self.prefix.lengths.max()) + int(self.suffix.lengths.max()) > MAX_WORDS:
            raise InputError(f"grammar derives sentences over {MAX_WORDS} words; not supported")

    # -- construction helpers ------------------------------------------------------------------

    def _block(self, slots: tuple[int, ...]) -> _Block:
        names = [self.grammar.slots[i] for i in slots]
        lengths = np.zeros(1, dtype=np.int64)
        for name in names:
            lengths = (lengths[:, None] + self._phrase_lengths[name][None, :]).ravel()
        by_length = np.argsort(lengths, kind="stable")
        edges = np.flatnonzero(np.diff(lengths[by_length])) + 1
        starts = [0, *edges.tolist()]
        stops = [*edges.tolist(), int(lengths.shape[0])]
        sizes = tuple(len(self.phrases[n]) for n in names)
        return _Block(
            slots=slots,
            sizes=sizes,
            lengths=lengths,
            by_length=by_length,
            bounds=tuple(zip(starts, stops, strict=True)),
        )

    @cached_property
    def _prefix_lookup(self) -> dict[tuple[str, ...], int]:
        return self._lookup(self.prefix)

    @cached_property
    def _suffix_lookup(self) -> dict[tuple[str, ...], int]:
        return self._lookup(self.suffix)

    def _lookup(self, block: _Block) -> dict[tuple[str, ...], int]:
        """Word tuple -> lowest block index deriving it (the first parse of an ambiguous one)."""
        table: dict[tuple[str, ...], int] = {}
        choices = [self.phrases[self.grammar.slots[slot]] for slot in block.slots]
        for index, combo in enumerate(itertools.product(*choices)):  # row-major = key order
            table.setdefault(sum(combo, ()), index)
        return table

    @cached_property
    def positions(self) -> Positions:
        """Every phrase at every sentence position, grouped by (position, length)."""
        return Positions.build(self)

    @cached_property
    def sentence_lengths(self) -> npt.NDArray[np.int16]:
        """Words per sentence for every key (static; the brute force divides by it)."""
        return np.add.outer(
            self.prefix.lengths.astype(np.int16), self.suffix.lengths.astype(np.int16)
        ).ravel()

    # -- per-call tables -----------------------------------------------------------------------

    def word_logprobs(self, word_probs: Mapping[str, float]) -> FloatArray:
        """log P(word) for the vocabulary, in order, rounded to 2**-32; P = 0 gives -inf quietly.

        Keys outside the vocabulary are ignored (a network may know more words than the grammar).
        """
        try:
            values = np.fromiter(
                map(word_probs.__getitem__, self.vocabulary), np.float64, len(self.vocabulary)
            )
        except KeyError:
            missing = [w for w in self.vocabulary if w not in word_probs]
            more = f" (and {len(missing) - 1} more)" if len(missing) > 1 else ""
            raise InputError(
                f"word probabilities lack the word {missing[0]!r}{more}; "
                f"every grammar word is needed: {', '.join(self.vocabulary)}"
            ) from None
        except (TypeError, ValueError) as exc:
            raise InputError(f"word probabilities must be numbers: {exc}") from None
        if not (values.min() >= 0.0 and values.max() <= 1.0 + _PROB_SLACK):  # NaN fails too
            bad = ~((values >= 0.0) & (values <= 1.0 + _PROB_SLACK))
            i = int(np.flatnonzero(bad)[0])
            raise InputError(
                f"word probability of {self.vocabulary[i]!r} is {float(values[i])!r}; "
                "a probability must be in [0, 1]"
            )
        with np.errstate(divide="ignore"):
            logs = np.log(np.minimum(values, 1.0))
        # multiplying by a power of two is exact, so this is rounding to multiples of 2**-32
        return np.round(logs * _SCALE) * (1.0 / _SCALE)

    def phrase_logprobs(self, word_lp: FloatArray) -> dict[str, FloatArray]:
        """Each phrase's log-probability: its words summed left to right."""
        ext = np.append(word_lp, 0.0)[self._table]
        acc = ext[:, 0].copy()
        for column in range(1, ext.shape[1]):
            acc += ext[:, column]
        return {name: acc[sl] for name, sl in self._slices.items()}

    def block_sums(self, word_lp: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Summed log-probability of every prefix and every suffix, in key order."""
        phrase_lp = self.phrase_logprobs(word_lp)
        return self._block_sum(self.prefix, phrase_lp), self._block_sum(self.suffix, phrase_lp)

    def _block_sum(self, block: _Block, phrase_lp: dict[str, FloatArray]) -> FloatArray:
        acc = np.zeros(1)
        for slot in block.slots:
            acc = (acc[:, None] + phrase_lp[self.grammar.slots[slot]][None, :]).ravel()
        return acc

    # -- keys <-> sentences ----------------------------------------------------------------------

    def split_keys(self, keys: IntArray) -> tuple[IntArray, IntArray]:
        """Sentence keys -> (prefix index, suffix index)."""
        return np.divmod(keys, self.suffix.size)

    def sentence(self, key: int) -> str:
        """The sentence string of a key."""
        p, s = divmod(int(key), self.suffix.size)
        prefix, suffix = self._prefix_strings[p], self._suffix_strings[s]
        return f"{prefix} {suffix}" if prefix and suffix else prefix or suffix

    @cached_property
    def _prefix_strings(self) -> list[str]:
        return self._strings(self.prefix)

    @cached_property
    def _suffix_strings(self) -> list[str]:
        return self._strings(self.suffix)

    def _strings(self, block: _Block) -> list[str]:
        choices = [self.phrase_strings[self.grammar.slots[slot]] for slot in block.slots]
        return [" ".join(filter(None, combo)) for combo in itertools.product(*choices)]

    def phrase_ranks(self, keys: IntArray) -> list[IntArray]:
        """Per slot, the rank of the chosen phrase (in `phrases[slot]`) for each key."""
        p, s = self.split_keys(np.asarray(keys, dtype=np.int64))
        out: list[IntArray] = []
        for block, idx in ((self.prefix, p), (self.suffix, s)):
            if block.sizes:
                out.extend(
                    np.asarray(r, dtype=np.int64) for r in np.unravel_index(idx, block.sizes)
                )
        return out

    def keys_from_ranks(self, ranks: list[IntArray]) -> IntArray:
        """Inverse of `phrase_ranks`: per-slot phrase ranks -> sentence keys (mixed radix)."""
        key = np.zeros_like(np.asarray(ranks[0], dtype=np.int64))
        for slot, r in enumerate(ranks):
            key = key * len(self.phrases[self.grammar.slots[slot]]) + r
        return key

    def parse(self, words: tuple[str, ...]) -> int | None:
        """The key of a word sequence, or None if the grammar does not derive it."""
        prefixes = self._prefix_lookup
        suffixes = self._suffix_lookup
        for cut in range(len(words) + 1):
            p = prefixes.get(words[:cut])
            if p is not None:
                s = suffixes.get(words[cut:])
                if s is not None:
                    return p * self.suffix.size + s
        return None

    def parse_lines(self, lines: Iterable[str], source: str = "sentences") -> IntArray:
        """Keys of the non-blank lines, in order; a clear error naming the first bad line."""
        keys: list[int] = []
        for lineno, line in enumerate(lines, 1):
            words = tuple(line.split())
            if not words:
                continue
            unknown = [w for w in words if w not in self._word_index]
            if unknown:
                raise InputError(
                    f"{source} line {lineno}: unknown word {unknown[0]!r} in {line.strip()!r}; "
                    f"valid words: {', '.join(self.vocabulary)}"
                )
            key = self.parse(words)
            if key is None:
                raise InputError(
                    f"{source} line {lineno}: {line.strip()!r} is not a sentence of the grammar "
                    f"({' '.join(self.grammar.slots)})"
                )
            keys.append(key)
        return np.asarray(keys, dtype=np.int64)

    # -- caching ---------------------------------------------------------------------------------

    @staticmethod
    def of(grammar: Grammar = DEFAULT_GRAMMAR) -> SentenceSpace:
        """The compiled space of a grammar, built once per grammar object."""
        hit = _CACHE.get(id(grammar))
        if hit is not None and hit[0] is grammar:
            return hit[1]
        space = SentenceSpace(grammar)
        _CACHE[id(grammar)] = (grammar, space)
        return space


_CACHE: dict[int, tuple[Grammar, SentenceSpace]] = {}


def final_scores(
    sums: FloatArray, lengths: npt.NDArray[np.integer], legacy_offset: bool
) -> FloatArray:
    """Length-normalised scores; with the reference implementation's offset if asked."""
    if legacy_offset:
        return np.asarray((1.0 + sums) / lengths, dtype=np.float64)
    return np.asarray(sums / lengths, dtype=np.float64)


def score_sentence(
    sentence: str, word_probs: Mapping[str, float], *, legacy_offset: bool = False
) -> float:
    """(1/L) Σ log P(w_k) over the words of any sentence (no grammar needed), −inf if a P is 0.

    Uses the same rounded log-probabilities as the N-best functions, so it gives the very same
    score for a sentence of the grammar.
    """
    words = sentence.split()
    if not words:
        raise InputError("cannot score an empty sentence; give at least one word")
    total = 1.0 if legacy_offset else 0.0
    for w in words:
        if w not in word_probs:
            raise InputError(
                f"word {w!r} has no probability; words given: {', '.join(sorted(word_probs))}"
            )
        p = float(word_probs[w])
        if not (0.0 <= p <= 1.0 + _PROB_SLACK):
            raise InputError(f"word probability of {w!r} is {p!r}; it must be in [0, 1]")
        total += _rounded_log(p)
    return total / len(words)


def _rounded_log(p: float) -> float:
    if p <= 0.0:
        return -math.inf
    return math.ldexp(
        round(math.ldexp(math.log(min(p, 1.0)), LOG_FRACTION_BITS)), -LOG_FRACTION_BITS
    )


def _has_word_prefix_pair(phrases: tuple[Phrase, ...]) -> bool:
    """Whether one phrase is a proper word-prefix of another (phrases sorted)."""
    return any(len(b) > len(a) and b[: len(a)] == a for a, b in itertools.pairwise(phrases))


def _best_split(sizes: list[int]) -> int:
    """The slot index splitting the slots into two blocks with the fewest entries in total."""
    best, best_cost = 0, math.inf
    for cut in range(len(sizes) + 1):
        cost = math.prod(sizes[:cut]) + math.prod(sizes[cut:])
        if cost < best_cost:
            best, best_cost = cut, cost
    return best
