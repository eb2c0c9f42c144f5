from pathlib import Path

import pytest

from beyond_self.cognition.grammar import DEFAULT_GRAMMAR, parse_grammar
from beyond_self.core.errors import InputError


def test_grammar_size_matches_hand_count() -> None:
    # agent 3; action 6 verbs x (V-s, V-ed, just V-ed, has V-ed, has just V-ed, is V-ing) = 36;
    # object "the [size] [color] shape" = 3 * 4 * 5 = 60; conjunction 2; effect 12.
    assert DEFAULT_GRAMMAR.count() == 3 * 36 * 60 * 2 * 60 * 12


def test_vocabulary_is_the_49_word_nodes(shared_data: Path) -> None:
    lines = (shared_data / "salvi2012" / "networkDefinition.txt").read_text().splitlines()
    words = {line.split()[0] for line in lines[8:] if line.strip()}
    assert len(words) == 49
    assert set(DEFAULT_GRAMMAR.vocabulary) == words


def test_every_sampled_sentence_of_the_article_is_in_the_grammar(shared_data: Path) -> None:
    path = shared_data / "saponaro2019" / "sentence_1000samples.txt"
    g = DEFAULT_GRAMMAR
    for line in path.read_text().splitlines():
        words = tuple(line.split())
        # greedy-free check: try every split of the words into the six slots
        assert _derives(words, list(g.slots), g), line


def _derives(words: tuple[str, ...], slots: list[str], g: object) -> bool:
    from beyond_self.cognition.grammar import Grammar

    assert isinstance(g, Grammar)
    if not slots:
        return not words
    return any(
        words[: len(p)] == p and _derives(words[len(p) :], slots[1:], g)
        for p in g.phrases[slots[0]]
    )


def test_bad_grammar_is_a_clear_error() -> None:
    with pytest.raises(InputError, match="defined twice"):
        parse_grammar("sentence = a\na = x\na = y")
    with pytest.raises(InputError, match="must name rules only"):
        parse_grammar("sentence = a word\na = x")
