"""A gesture model set on disk: written as our versioned JSON, read from it or from one of the
article's MATLAB files (`.mat`), whichever the name says."""

from __future__ import annotations

import json
from pathlib import Path

from beyond_self.cognition.gestures.hmm import GestureModels
from beyond_self.cognition.gestures.matlab import load_matlab_models
from beyond_self.core.errors import InputError


def save_models(models: GestureModels, path: str | Path) -> Path:
    """Write a model set as versioned JSON (the format: cognition.gestures.hmm)."""
    p = Path(path)
    if p.suffix.lower() != ".json":
        raise InputError(f"model file {p} must end in .json (the only write format)")
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(models.to_dict(), indent=1) + "\n", encoding="utf-8")
    return p


def load_models(path: str | Path, *, include_garbage: bool = False) -> GestureModels:
    """Read a model set: our JSON, or one of the article's MATLAB files (`.mat`)."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"model file {p} does not exist; valid: a .json model file or a .mat file")
    if p.suffix.lower() == ".mat":
        return load_matlab_models(p, include_garbage=include_garbage)
    if p.suffix.lower() != ".json":
        raise InputError(f"unknown model file type {p.suffix!r}; valid: .json, .mat")
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{p} is not valid JSON ({exc.__class__.__name__})") from None
    models = GestureModels.from_dict(data)
    return models.including("garbage") if include_garbage and "garbage" in models.extra else models
