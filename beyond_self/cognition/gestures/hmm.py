"""Left-to-right GMM-HMMs, one per action: the model class and the model file format.

One class holds every gesture model, trained here or loaded from the article's MATLAB files, so
nothing downstream cares where a model came from. A model file is JSON, never pickle, with floats
written in shortest round-trip form so a save/load cycle is bit-exact: its feature space, its
floor (below it under every model a gesture is no action), the actions and each model's start
probabilities, transitions, weights, means and covariances (docs/science/gestures.md).
Version 1 files hold "position" models and still load. Training is `training`; reading and
writing a model file (ours or a .mat) is `model_files`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from beyond_self.cognition.gestures.features import POSITION, check_space
from beyond_self.core.errors import InputError, unknown

LOG_2PI = float(np.log(2.0 * np.pi))
FloatArray = NDArray[np.float64]

FORMAT = "beyond-self/gesture-models"
VERSION = 2
READABLE_VERSIONS = (1, 2)
_TOL = 1e-6


@dataclass(frozen=True, eq=False)
class GestureHMM:
    """One HMM with Gaussian-mixture emissions (full covariances).

    Shapes: startprob (Q,), transmat (Q, Q) with row = from-state, weights (Q, M),
    means (Q, M, D), covars (Q, M, D, D). Validated on construction.
    """

    startprob: FloatArray
    transmat: FloatArray
    weights: FloatArray
    means: FloatArray
    covars: FloatArray

    def __post_init__(self) -> None:
        arrays = {}
        for name in ("startprob", "transmat", "weights", "means", "covars"):
            value = np.array(getattr(self, name), dtype=np.float64)
            if not np.all(np.isfinite(value)):
                raise InputError(f"HMM {name} holds NaN or infinite values; valid: finite numbers")
            value.setflags(write=False)
            object.__setattr__(self, name, value)
            arrays[name] = value
        s, a, w, mu, cov = (
            arrays[k] for k in ("startprob", "transmat", "weights", "means", "covars")
        )
        if s.ndim != 1 or s.size == 0:
            raise InputError(f"HMM startprob has shape {s.shape}; valid: (Q,) with Q >= 1")
        q = s.size
        if a.shape != (q, q):
            raise InputError(f"HMM transmat has shape {a.shape}; valid: ({q}, {q})")
        if w.ndim != 2 or w.shape[0] != q or w.shape[1] == 0:
            raise InputError(f"HMM weights have shape {w.shape}; valid: ({q}, M) with M >= 1")
        m = w.shape[1]
        if mu.ndim != 3 or mu.shape[:2] != (q, m) or mu.shape[2] == 0:
            raise InputError(f"HMM means have shape {mu.shape}; valid: ({q}, {m}, D)")
        d = mu.shape[2]
        if cov.shape != (q, m, d, d):
            raise InputError(f"HMM covars have shape {cov.shape}; valid: ({q}, {m}, {d}, {d})")
        for name, probs in (("startprob", s[None, :]), ("transmat", a), ("weights", w)):
            if np.any(probs < 0) or np.any(np.abs(probs.sum(axis=-1) - 1.0) > _TOL):
                raise InputError(
                    f"HMM {name} is not a probability table; valid: non-negative rows summing to 1"
                )
        if not np.allclose(cov, np.swapaxes(cov, -1, -2), rtol=1e-9, atol=1e-12):
            raise InputError("HMM covars are not symmetric; valid: symmetric positive definite")
        try:
            np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:
            raise InputError(
                "HMM covars are not positive definite; valid: symmetric positive definite"
            ) from None

    @property
    def n_states(self) -> int:
        return int(self.startprob.size)

    @property
    def n_mix(self) -> int:
        return int(self.weights.shape[1])

    @property
    def n_features(self) -> int:
        return int(self.means.shape[2])

    @property
    def is_left_to_right(self) -> bool:
        """Starts in the first state and never moves backwards."""
        return bool(self.startprob[0] == 1.0 and not np.any(np.tril(self.transmat, k=-1) != 0.0))

    def to_dict(self) -> dict[str, Any]:
        return {
            "startprob": self.startprob.tolist(),
            "transmat": self.transmat.tolist(),
            "weights": self.weights.tolist(),
            "means": self.means.tolist(),
            "covars": self.covars.tolist(),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> GestureHMM:
        keys = ("startprob", "transmat", "weights", "means", "covars")
        missing = [k for k in keys if k not in data]
        if missing:
            raise InputError(f"HMM entry lacks {', '.join(missing)}; valid keys: {', '.join(keys)}")
        try:
            arrays = {k: np.asarray(data[k], dtype=np.float64) for k in keys}
        except (TypeError, ValueError):
            raise InputError("HMM entry holds ragged or non-numeric arrays") from None
        return cls(**arrays)

    def to_hmmlearn(self) -> Any:
        """The same model as an `hmmlearn.hmm.GMMHMM` (for reference scoring and benchmarks)."""
        from hmmlearn.hmm import GMMHMM

        model = GMMHMM(
            n_components=self.n_states,
            n_mix=self.n_mix,
            covariance_type="full",
            init_params="",
            params="",
        )
        model.n_features = self.n_features
        model.startprob_ = self.startprob.copy()
        model.transmat_ = self.transmat.copy()
        model.weights_ = self.weights.copy()
        model.means_ = self.means.copy()
        model.covars_ = self.covars.copy()
        return model

    @classmethod
    def from_hmmlearn(cls, model: Any) -> GestureHMM:
        if getattr(model, "covariance_type", "full") != "full":
            raise InputError("only full-covariance GMMHMMs convert; valid: covariance_type='full'")
        return cls(
            startprob=model.startprob_,
            transmat=model.transmat_,
            weights=model.weights_,
            means=model.means_,
            covars=model.covars_,
        )


@dataclass(frozen=True, eq=False)
class GestureModels:
    """The set of per-action HMMs, in a fixed action order (the posterior's order).

    `extra` holds models loaded alongside but kept out of the posterior (the reference garbage
    model); `including()` moves one into the action set when it is wanted as a class.
    """

    actions: tuple[str, ...]
    hmms: tuple[GestureHMM, ...]
    extra: Mapping[str, GestureHMM] = field(default_factory=dict)
    meta: Mapping[str, Any] = field(default_factory=dict)
    features: str = POSITION  # the feature space the models were trained in
    floor: float | None = None  # per-frame log-likelihood below which no action fits

    def __post_init__(self) -> None:
        object.__setattr__(self, "actions", tuple(self.actions))
        object.__setattr__(self, "hmms", tuple(self.hmms))
        dim = check_space(self.features)
        if self.floor is not None and not math.isfinite(self.floor):
            raise InputError(f"gesture model floor {self.floor!r}; valid: a finite number")
        if not self.actions:
            raise InputError("a gesture model set needs at least one action")
        if len(set(self.actions)) != len(self.actions):
            raise InputError(f"duplicate actions in {self.actions}; each action needs one model")
        if len(self.actions) != len(self.hmms):
            raise InputError(
                f"{len(self.actions)} actions but {len(self.hmms)} HMMs; one per action"
            )
        dims = {h.n_features for h in (*self.hmms, *self.extra.values())}
        if len(dims) != 1:
            raise InputError(f"HMMs disagree on the feature dimension ({sorted(dims)}); use one")
        if dims != {dim}:
            raise InputError(
                f"HMMs have {dims.pop()} features but the {self.features!r} space has {dim}"
            )

    @property
    def n_features(self) -> int:
        return self.hmms[0].n_features

    def __len__(self) -> int:
        return len(self.actions)

    def __getitem__(self, action: str) -> GestureHMM:
        if action in self.actions:
            return self.hmms[self.actions.index(action)]
        if action in self.extra:
            return self.extra[action]
        raise unknown("gesture model", action, (*self.actions, *self.extra))

    def including(self, *names: str) -> GestureModels:
        """A model set whose posterior also covers these `extra` models (e.g. "garbage")."""
        for name in names:
            if name not in self.extra:
                raise unknown("extra gesture model", name, tuple(self.extra))
        return GestureModels(
            actions=(*self.actions, *names),
            hmms=(*self.hmms, *(self.extra[n] for n in names)),
            extra={k: v for k, v in self.extra.items() if k not in names},
            meta=self.meta,
            features=self.features,
            floor=self.floor,
        )

    def subset(self, actions: Sequence[str]) -> GestureModels:
        """Only these actions, in this order."""
        return GestureModels(
            actions=tuple(actions),
            hmms=tuple(self[a] for a in actions),
            meta=self.meta,
            features=self.features,
            floor=self.floor,
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "version": VERSION,
            "features": self.features,
            "floor": self.floor,
            "actions": list(self.actions),
            "models": {a: h.to_dict() for a, h in zip(self.actions, self.hmms, strict=True)},
            "extra": {k: h.to_dict() for k, h in self.extra.items()},
            "meta": dict(self.meta),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> GestureModels:
        if not isinstance(data, Mapping) or data.get("format") != FORMAT:
            raise InputError(f"not a gesture model file; valid: JSON with format {FORMAT!r}")
        version = data.get("version")
        if version not in READABLE_VERSIONS:
            raise InputError(
                f"gesture model file version {version!r} is not supported; "
                f"valid: {', '.join(map(str, READABLE_VERSIONS))}"
            )
        features = data.get("features", POSITION) if version >= 2 else POSITION
        floor = data.get("floor") if version >= 2 else None
        if not isinstance(features, str) or not (
            floor is None or (isinstance(floor, int | float) and not isinstance(floor, bool))
        ):
            raise InputError("gesture model file: 'features' must be a name, 'floor' a number")
        actions = data.get("actions")
        models = data.get("models")
        if not isinstance(actions, list) or not isinstance(models, Mapping):
            raise InputError("gesture model file lacks 'actions' (list) or 'models' (object)")
        missing = [a for a in actions if a not in models]
        if missing:
            raise InputError(f"gesture model file has no model for {', '.join(map(str, missing))}")
        extra = data.get("extra", {})
        return cls(
            actions=tuple(str(a) for a in actions),
            hmms=tuple(GestureHMM.from_dict(models[a]) for a in actions),
            extra={str(k): GestureHMM.from_dict(v) for k, v in extra.items()},
            meta=dict(data.get("meta", {})),
            features=features,
            floor=None if floor is None else float(floor),
        )


def logsumexp_last(a: FloatArray) -> FloatArray:
    """log(sum(exp(a))) over the last axis; -inf where every term is -inf, without warnings."""
    top = a.max(axis=-1, keepdims=True)
    top = np.where(np.isfinite(top), top, 0.0)
    with np.errstate(divide="ignore", under="ignore"):
        return cast(np.ndarray, np.log(np.exp(a - top).sum(axis=-1)) + top[..., 0])


def log_prior(priors: ArrayLike | None, n: int) -> FloatArray:
    """Log of action priors (equal when None), checked."""
    if priors is None:
        return np.full(n, -math.log(n))
    p = np.asarray(priors, dtype=np.float64)
    if p.shape != (n,) or np.any(p < 0) or not np.all(np.isfinite(p)) or p.sum() <= 0:
        raise InputError(
            f"priors {priors!r} are invalid; valid: {n} non-negative numbers, not all 0"
        )
    with np.errstate(divide="ignore"):
        return cast(np.ndarray, np.log(p / p.sum()))
