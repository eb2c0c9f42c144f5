"""Random sentences drawn the way HTK's HSGen draws them from the network HParse builds.

HSGen walks a network with one node per word occurrence and picks uniformly among the words that
can come next, so after "the" each of 10 words has 1/10 (a size word in 20% of objects, not 50%),
and the five verb forms are equally likely. The article's sampled lists agree with that reading
on every slot and reject "each optional part is a coin flip" (chi-square,
tests/test_descriptions_sampling.py). Each slot's rule is compiled to its First/Follow/Last sets
(a Glushkov automaton): leaving a slot is a choice among a fixed number of words, so slots are
independent and a sentence is one categorical draw per slot. A slot that can be empty would
couple its neighbours; such grammars are refused.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from beyond_self.cognition.descriptions.space import FloatArray, IntArray, SentenceSpace
from beyond_self.cognition.grammar import _TOKEN, DEFAULT_GRAMMAR, Grammar, Phrase
from beyond_self.core.errors import InputError


@dataclass
class _Automaton:
    """Word positions of one slot with the Glushkov sets."""

    words: list[str] = field(default_factory=list)
    follow: list[list[int]] = field(default_factory=list)
    first: list[int] = field(default_factory=list)
    last: list[int] = field(default_factory=list)
    nullable: bool = False


class _Compiler:
    def __init__(self, rules: dict[str, str]) -> None:
        self.rules = rules
        self.auto = _Automaton()

    def compile(self, body: str) -> _Automaton:
        first, last, nullable = self._body(body, 0)
        self.auto.first, self.auto.last, self.auto.nullable = first, last, nullable
        return self.auto

    def _body(self, body: str, depth: int) -> tuple[list[int], list[int], bool]:
        if depth > 20:
            raise InputError("grammar is recursive; only finite grammars are supported")
        tokens = _TOKEN.findall(body)
        result, i = self._alt(tokens, 0, depth)
        if i != len(tokens):
            raise InputError(f"grammar rule body {body!r}: unexpected {tokens[i]!r}")
        return result

    def _alt(
        self, tokens: list[str], i: int, depth: int
    ) -> tuple[tuple[list[int], list[int], bool], int]:
        first: list[int] = []
        last: list[int] = []
        nullable = False
        while True:
            (f, la, nu), i = self._seq(tokens, i, depth)
            first += f
            last += la
            nullable = nullable or nu
            if i < len(tokens) and tokens[i] == "|":
                i += 1
                continue
            return (first, last, nullable), i

    def _seq(
        self, tokens: list[str], i: int, depth: int
    ) -> tuple[tuple[list[int], list[int], bool], int]:
        first: list[int] = []
        last: list[int] = []
        nullable = True
        while i < len(tokens) and tokens[i] not in ("|", "]"):
            (f, la, nu), i = self._item(tokens, i, depth)
            for p in last:
                self.auto.follow[p] += f
            first = first + f if nullable else first
            last = la + last if nu else la
            nullable = nullable and nu
        return (first, last, nullable), i

    def _item(
        self, tokens: list[str], i: int, depth: int
    ) -> tuple[tuple[list[int], list[int], bool], int]:
        tok = tokens[i]
        if tok == "[":
            (f, la, _), i = self._alt(tokens, i + 1, depth)
            if i >= len(tokens) or tokens[i] != "]":
                raise InputError("grammar: '[' without its ']'")
            return (f, la, True), i + 1
        if tok in self.rules:
            return self._body(self.rules[tok], depth + 1), i + 1
        pos = len(self.auto.words)
        self.auto.words.append(tok)
        self.auto.follow.append([])
        return ([pos], [pos], False), i + 1


def _slot_bodies(grammar: Grammar) -> dict[str, str]:
    """Each slot's rule body; a grammar without rules has its phrases as alternatives."""
    names = dict.fromkeys(grammar.slots)
    if grammar.rules:
        return {name: grammar.rules[name] for name in names}
    return {name: " | ".join(" ".join(p) for p in grammar.phrases[name]) for name in names}


def hsgen_phrase_probabilities(grammar: Grammar = DEFAULT_GRAMMAR) -> list[dict[Phrase, float]]:
    """Per slot position, the probability HSGen's walk gives each phrase (they sum to 1)."""
    rules = grammar.rules
    bodies = _slot_bodies(grammar)
    autos = [_Compiler(rules).compile(bodies[name]) for name in grammar.slots]
    for name, auto in zip(grammar.slots, autos, strict=True):
        if auto.nullable:
            raise InputError(
                f"grammar slot {name!r} can be empty; random generation needs every slot to "
                "produce at least one word"
            )
    out: list[dict[Phrase, float]] = []
    for j, auto in enumerate(autos):
        exit_weight = len(set(autos[j + 1].first)) if j + 1 < len(autos) else 1
        probs: dict[Phrase, float] = {}
        _walk(auto, exit_weight, probs)
        expected = set(grammar.phrases[grammar.slots[j]])
        if set(probs) != expected:
            raise InputError(f"grammar slot {grammar.slots[j]!r}: rules and phrases disagree")
        out.append(probs)
    return out


def _walk(auto: _Automaton, exit_weight: int, probs: dict[Phrase, float]) -> None:
    """Add every path's probability to the phrase it spells (depth-first; paths are few)."""
    first = list(dict.fromkeys(auto.first))
    last = set(auto.last)
    stack: list[tuple[int, Phrase, float]] = [(p, (auto.words[p],), 1 / len(first)) for p in first]
    while stack:
        p, words, prob = stack.pop()
        nexts = list(dict.fromkeys(auto.follow[p]))
        ends = p in last
        total = len(nexts) + (exit_weight if ends else 0)
        if ends:
            probs[words] = probs.get(words, 0.0) + prob * exit_weight / total
        stack.extend((q, (*words, auto.words[q]), prob / total) for q in nexts)


def slot_distributions(grammar: Grammar = DEFAULT_GRAMMAR) -> list[FloatArray]:
    """Per slot position, HSGen's phrase probabilities aligned with `SentenceSpace.phrases`."""
    hit = _DIST_CACHE.get(id(grammar))
    if hit is not None and hit[0] is grammar:
        return hit[1]
    space = SentenceSpace.of(grammar)
    per_slot = hsgen_phrase_probabilities(grammar)
    dists = []
    for name, probs in zip(grammar.slots, per_slot, strict=True):
        p = np.array([probs[phrase] for phrase in space.phrases[name]])
        dists.append(p / p.sum())
    _DIST_CACHE[id(grammar)] = (grammar, dists)
    return dists


# Samples are drawn at once, one int64 per slot and sample: a million is ~0.1 GB, the article
# drew 10,000. More is refused with the limit in the message instead of exhausting memory.
SAMPLES_MAX = 1_000_000

_DIST_CACHE: dict[int, tuple[Grammar, list[FloatArray]]] = {}


def sample_keys(count: int, seed: int, *, grammar: Grammar = DEFAULT_GRAMMAR) -> IntArray:
    """Keys of `count` sentences drawn like HSGen (repeats kept, in draw order)."""
    if isinstance(count, bool) or not isinstance(count, int | np.integer) or count < 0:
        raise InputError(f"number of samples must be a non-negative integer, got {count!r}")
    if count > SAMPLES_MAX:
        raise InputError(f"number of samples {count} is over the limit; valid: 0..{SAMPLES_MAX}")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise InputError(f"seed must be a non-negative integer, got {seed!r}")
    space = SentenceSpace.of(grammar)
    rng = np.random.default_rng(int(seed))
    ranks = [rng.choice(p.shape[0], size=int(count), p=p) for p in slot_distributions(grammar)]
    return space.keys_from_ranks(ranks)


def sample_sentences(count: int, seed: int, *, grammar: Grammar = DEFAULT_GRAMMAR) -> list[str]:
    """`count` random sentences like `HSGen -n count` (repeats kept), reproducible by seed."""
    space = SentenceSpace.of(grammar)
    return [space.sentence(int(k)) for k in sample_keys(count, seed, grammar=grammar)]
