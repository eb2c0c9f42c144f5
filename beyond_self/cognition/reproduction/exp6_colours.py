"""Experiment 6, object words: the best sentence naming a colour, for grasp and touch on two
green objects (docs/science/reproduce.md)."""

from __future__ import annotations

from beyond_self.cognition.descriptions import nbest_exact, nbest_from_file
from beyond_self.cognition.fusion import ACTION
from beyond_self.cognition.reproduction.inputs import Inputs

EXP6_OBJECTS = (("green1", "box"), ("green2", "circle"))

COLOUR_WORD = r"\b(green|yellow|blue)\b"


def exp6(inputs: Inputs) -> dict[str, dict[str, str]]:
    """The best sentence naming a colour, for grasp/touch on a green1 box and a green2 sphere."""
    out: dict[str, dict[str, str]] = {}
    for colour, shape in EXP6_OBJECTS:
        for action in ("grasp", "touch"):
            words = inputs.model.word_probabilities(
                {ACTION: action, "Color": colour, "Shape": shape}
            )
            from_file = nbest_from_file(
                inputs.sentences, words, 1, legacy_offset=True, require=COLOUR_WORD
            )
            exact = nbest_exact(words, 1, require=COLOUR_WORD)
            out[f"{action} {colour} {shape}"] = {
                "file": from_file[0].sentence if from_file else "",
                "exact": exact[0].sentence if exact else "",
            }
    return out
