"""The description grammar of the article, as data.

The grammar is written once, below, in a small EBNF-like notation (`[x]` optional, `a | b`
alternatives, lower-case names of other rules, everything else a word), and expanded into a
`Grammar`: the top rule's sequence of slots and, for each slot, every word sequence it can take.
Every consumer (the narrator of the synthetic data set, random sentence generation, sentence
scoring, the exact N-best search) reads this one definition, so the vocabulary cannot drift.

The top rule is a flat sequence of slots whose expansions are independent of each other, which is
what lets the N-best search treat each slot as an independent choice.
"""

from __future__ import annotations

import itertools
import re
from dataclasses import dataclass, field
from functools import cached_property

from beyond_self.core.errors import InputError

_VERBS = {  # stem: (third person, past, -ing)
    "touch": ("touches", "touched", "touching"),
    "poke": ("pokes", "poked", "poking"),
    "tap": ("taps", "tapped", "tapping"),
    "push": ("pushes", "pushed", "pushing"),
    "grasp": ("grasps", "grasped", "grasping"),
    "pick": ("picks", "picked", "picking"),
}

GRAMMAR_TEXT = "\n".join(
    [
        "sentence = agent action object conjunction object effect",
        "agent = the robot | he | baltazar",
        "action = " + " | ".join(f"v_{stem}" for stem in _VERBS),
        *(
            f"v_{stem} = {s} | [has] [just] {ed} | is {ing}"
            for stem, (s, ed, ing) in _VERBS.items()
        ),
        "object = the [size] [color] shape",
        "size = big | small",
        "color = green | yellow | blue",
        "shape = sphere | ball | cube | box | square",
        "conjunction = and | but",
        "effect = is inert | is still | moves | is moving | slides | is sliding | rolls"
        " | is rolling | rises | is rising | falls | is falling",
    ]
)

Phrase = tuple[str, ...]


@dataclass(frozen=True)
class Grammar:
    """A flat sentence grammar: `slots` in order, each with the phrases it can expand to."""

    slots: tuple[str, ...]
    phrases: dict[str, tuple[Phrase, ...]]
    # The rule bodies as written (name -> body), kept so that random generation can walk the
    # grammar's own structure the way HTK's HSGen walks the network HParse builds from it; empty
    # for a grammar built from phrases alone (each phrase is then one alternative of its slot).
    rules: dict[str, str] = field(default_factory=dict, compare=False)

    @cached_property
    def vocabulary(self) -> tuple[str, ...]:
        """Every terminal word, in order of first appearance in the slots."""
        seen: dict[str, None] = {}
        for slot in self.slots:
            for phrase in self.phrases[slot]:
                seen.update(dict.fromkeys(phrase))
        return tuple(seen)

    def count(self) -> int:
        """How many sentences the grammar produces."""
        n = 1
        for slot in self.slots:
            n *= len(self.phrases[slot])
        return n

    def sentences(self) -> itertools.product[tuple[Phrase, ...]]:
        """Every sentence as a tuple of phrases, one per slot (millions: iterate, don't list)."""
        return itertools.product(*(self.phrases[s] for s in self.slots))


_TOKEN = re.compile(r"\[|\]|\||[^\s\[\]|]+")


def _expand(body: str, rules: dict[str, str], depth: int = 0) -> list[Phrase]:
    """All word sequences a rule body derives (alternatives, optionals, rule references)."""
    if depth > 20:
        raise InputError("grammar is recursive; only finite grammars are supported")
    alternatives: list[Phrase] = []
    for alt in _split_top(body):
        sequences: list[Phrase] = [()]
        tokens = _TOKEN.findall(alt)
        i = 0
        while i < len(tokens):
            tok = tokens[i]
            if tok == "[":
                close = tokens.index("]", i)
                inner = _expand(" ".join(tokens[i + 1 : close]), rules, depth + 1)
                choices: list[Phrase] = [(), *inner]
                i = close + 1
            else:
                choices = _expand(rules[tok], rules, depth + 1) if tok in rules else [(tok,)]
                i += 1
            sequences = [s + c for s in sequences for c in choices]
        alternatives.extend(sequences)
    return alternatives


def _split_top(body: str) -> list[str]:
    """Split a rule body on `|` outside brackets."""
    parts: list[str] = []
    current: list[str] = []
    depth = 0
    for tok in _TOKEN.findall(body):
        depth += tok == "["
        depth -= tok == "]"
        if tok == "|" and depth == 0:
            parts.append(" ".join(current))
            current = []
        else:
            current.append(tok)
    parts.append(" ".join(current))
    return parts


def parse_grammar(text: str, top: str = "sentence") -> Grammar:
    """Parse the notation above; the top rule must be a plain sequence of rule names."""
    rules: dict[str, str] = {}
    for lineno, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        name, sep, body = line.partition("=")
        if not sep or not name.strip().isidentifier():
            raise InputError(f"grammar line {lineno}: expected 'name = body', got {line!r}")
        if name.strip() in rules:
            raise InputError(f"grammar line {lineno}: rule {name.strip()!r} defined twice")
        rules[name.strip()] = body.strip()
    if top not in rules:
        raise InputError(f"grammar has no top rule {top!r}; rules: {', '.join(rules)}")
    slots = tuple(rules[top].split())
    missing = [s for s in slots if s not in rules]
    if missing:
        raise InputError(f"top rule {top!r} must name rules only; not rules: {', '.join(missing)}")
    phrases = {s: tuple(dict.fromkeys(_expand(rules[s], rules))) for s in dict.fromkeys(slots)}
    return Grammar(slots=slots, phrases=phrases, rules=rules)


DEFAULT_GRAMMAR = parse_grammar(GRAMMAR_TEXT)
