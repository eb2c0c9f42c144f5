"""The gesture models every service and demo uses by default: HMMs trained on synthetic gestures.

They have never seen a person: they are trained on the simulator's gestures (whose shapes and
tempi follow the article's recordings), in the "motion" feature space. Training takes minutes,
so the result ships with the package; `beyond gesture train -o
cognition/gestures/data/synthetic_models.json` regenerates it byte for byte (60 gestures per
action, seed 0, 6 states, 3 Gaussians, at most 30 EM iterations).
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

from beyond_self.cognition.gestures.hmm import GestureModels
from beyond_self.cognition.gestures.model_files import load_models
from beyond_self.cognition.variables import ACTIONS
from beyond_self.core.errors import InputError

DEFAULT_MODELS_PATH = Path(__file__).with_name("data") / "synthetic_models.json"


@cache
def default_models() -> GestureModels:
    return load_models(DEFAULT_MODELS_PATH)


def pipeline_models(path: str | Path | None = None) -> GestureModels:
    """The gesture models a pipeline runs: the default ones, or those of a file, which must
    recognise exactly the actions the network reasons about (their posterior is its soft
    evidence on Action); a file for other actions is an InputError naming both sets."""
    models = load_models(Path(path)) if path else default_models()
    if set(models.actions) != set(ACTIONS):
        raise InputError(
            f"gesture models {path} recognise {', '.join(models.actions)}; the pipeline needs "
            f"models for exactly {', '.join(ACTIONS)}"
        )
    return models
