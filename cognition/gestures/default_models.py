"""The gesture models every service and demo uses by default: HMMs trained on synthetic gestures.

Training takes about 20 s, so the result ships with the package. It is regenerated, byte for
byte, by

    beyond gesture train -o cognition/gestures/data/synthetic_models.json

(30 synthetic gestures per action, seed 0, 6 states, 3 Gaussians); a test checks that it still
is what that command makes.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

from beyond_self.cognition.gestures.hmm import GestureModels, load_models

DEFAULT_MODELS_PATH = Path(__file__).with_name("data") / "synthetic_models.json"


@cache
def default_models() -> GestureModels:
    return load_models(DEFAULT_MODELS_PATH)
