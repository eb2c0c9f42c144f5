"""Experiment 5, N-best descriptions: of the yellow ball with the recorded gesture, and of a
grasp said with 'and' or with 'but' (docs/science/reproduce.md)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from beyond_self.cognition.descriptions import nbest_exact, nbest_from_file
from beyond_self.cognition.fusion import fuse_words
from beyond_self.cognition.reproduction.exp4_words import EXP4_OBSERVED
from beyond_self.cognition.reproduction.inputs import Inputs

EXP5_GRASP = {
    "and": {"Action": "grasp", "ObjVel": "medium"},
    "but": {"Action": "grasp", "ObjVel": "slow"},
}


def exp5(inputs: Inputs, gesture: Mapping[str, float]) -> dict[str, Any]:
    """N-best lists: the yellow ball with the recorded gesture; grasp with 'and' and with 'but'."""
    model, sentences = inputs.model, inputs.sentences
    gesture_words = fuse_words(model, EXP4_OBSERVED, gesture)
    out: dict[str, Any] = {
        "gesture": {
            "file": nbest_from_file(sentences, gesture_words, 10, legacy_offset=True),
            "exact": nbest_exact(gesture_words, 10),
        }
    }
    for conj, observed in EXP5_GRASP.items():
        words = model.word_probabilities(observed)
        out[conj] = {
            "file": nbest_from_file(sentences, words, 10, legacy_offset=True),
            "exact": nbest_exact(words, 10),
            "p_and": words["and"],
            "p_but": words["but"],
        }
    return out
