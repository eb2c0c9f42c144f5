"""Left-to-right GMM-HMMs, one per action: the model class, training, and the model file format.

One class holds every gesture model, trained here or loaded from the article's MATLAB files, so
nothing downstream cares where a model came from. A model file is JSON, never pickle, with floats
written in shortest round-trip form so a save/load cycle is bit-exact: its feature space, its
floor (below it under every model a gesture is no action), the actions and each model's start
probabilities, transitions, weights, means and covariances (docs/science/gestures.md).
Version 1 files hold "position" models and still load.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from beyond_self.cognition.gestures.features import MOTION, POSITION, check_space
from beyond_self.cognition.variables import ACTIONS
from beyond_self.core.errors import InputError, unknown

LOG_2PI = float(np.log(2.0 * np.pi))
FloatArray = NDArray[np.float64]

FORMAT = "beyond-self/gesture-models"
VERSION = 2
READABLE_VERSIONS = (1, 2)
_TOL = 1e-6
# nats per frame below the worst-fitting training gesture: people are sloppier than a simulator
FLOOR_MARGIN = 15.0


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


def save_models(models: GestureModels, path: str | Path) -> Path:
    """Write a model set as versioned JSON (see the module docstring)."""
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
        from beyond_self.cognition.gestures.matlab import load_matlab_models

        return load_matlab_models(p, include_garbage=include_garbage)
    if p.suffix.lower() != ".json":
        raise InputError(f"unknown model file type {p.suffix!r}; valid: .json, .mat")
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{p} is not valid JSON ({exc.__class__.__name__})") from None
    models = GestureModels.from_dict(data)
    return models.including("garbage") if include_garbage and "garbage" in models.extra else models


# ---------------------------------------------------------------------------------------------
# Training


@dataclass(frozen=True)
class TrainingConfig:
    """How to train one left-to-right GMM-HMM per action.

    `max_jump` is the longest forward step (1: self-loop or next state only). `min_covar` is a
    covariance floor entered as one pseudo-observation with covariance min_covar * I (an inverse
    Wishart prior), which keeps rarely used mixture components from collapsing.
    """

    n_states: int = 6
    n_mix: int = 3
    n_iter: int = 30
    tol: float = 1e-3
    min_covar: float = 1e-3
    max_jump: int = 1
    seed: int = 0

    def __post_init__(self) -> None:
        if self.n_states < 1 or self.n_mix < 1 or self.n_iter < 0:
            raise InputError("training needs n_states >= 1, n_mix >= 1 and n_iter >= 0")
        if self.max_jump < 1 or not self.min_covar > 0 or not self.tol > 0:
            raise InputError("training needs max_jump >= 1, min_covar > 0 and tol > 0")


def left_to_right_transmat(n_states: int, mean_duration: float, max_jump: int = 1) -> FloatArray:
    """A left-to-right transition matrix whose states last `mean_duration` frames on average."""
    stay = 1.0 - 1.0 / max(mean_duration, 1.0 + 1e-9)
    a = np.zeros((n_states, n_states))
    for i in range(n_states):
        reach = list(range(i + 1, min(i + max_jump, n_states - 1) + 1))
        if not reach:
            a[i, i] = 1.0
            continue
        a[i, i] = stay
        a[i, reach] = (1.0 - stay) / len(reach)
    return a


def _check_sequences(sequences: Sequence[ArrayLike], n_states: int, what: str) -> list[FloatArray]:
    if not sequences:
        raise InputError(f"no training sequences for {what}; at least one is needed")
    out = []
    dim: int | None = None
    for i, seq in enumerate(sequences):
        x = np.asarray(seq, dtype=np.float64)
        if x.ndim != 2:
            raise InputError(f"{what} sequence {i} has shape {x.shape}; valid: (T, D)")
        if dim is not None and x.shape[1] != dim:
            raise InputError(f"{what} sequence {i} has {x.shape[1]} features, others {dim}")
        dim = x.shape[1]
        if x.shape[0] < n_states:
            raise InputError(
                f"{what} sequence {i} is too short ({x.shape[0]} frames); "
                f"valid: at least {n_states} frames (one per state)"
            )
        if not np.all(np.isfinite(x)):
            raise InputError(f"{what} sequence {i} holds NaN or infinite values")
        out.append(x)
    return out


def _initial_emissions(
    seqs: list[FloatArray], config: TrainingConfig, rng: np.random.Generator
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Weights, means, covariances from a uniform split of every sequence into Q segments."""
    from scipy.cluster.vq import kmeans2

    q, m = config.n_states, config.n_mix
    d = seqs[0].shape[1]
    pools: list[list[FloatArray]] = [[] for _ in range(q)]
    for x in seqs:
        bounds = np.linspace(0, len(x), q + 1).round().astype(int)
        for s in range(q):
            pools[s].append(x[bounds[s] : bounds[s + 1]])
    floor = config.min_covar * np.eye(d)
    weights = np.full((q, m), 1.0 / m)
    means = np.zeros((q, m, d))
    covars = np.zeros((q, m, d, d))
    for s in range(q):
        data = np.concatenate(pools[s])
        state_cov = np.cov(data.T, bias=True).reshape(d, d) + floor if len(data) > 1 else floor
        labels = np.zeros(len(data), dtype=int)
        if m > 1 and len(data) >= m:
            seed = int(rng.integers(2**31 - 1))
            _, labels = kmeans2(data, m, minit="++", seed=seed)
        for c in range(m):
            members = data[labels == c]
            if len(members) == 0:
                means[s, c] = data[rng.integers(len(data))]
                covars[s, c] = state_cov
                continue
            means[s, c] = members.mean(axis=0)
            covars[s, c] = (
                np.cov(members.T, bias=True).reshape(d, d) + floor
                if len(members) > d
                else state_cov
            )
            weights[s, c] = len(members) / len(data)
        weights[s] /= weights[s].sum()
    return weights, means, covars


def train_hmm(
    sequences: Sequence[ArrayLike], config: TrainingConfig, *, what: str = "action"
) -> GestureHMM:
    """Train one left-to-right GMM-HMM with hmmlearn's EM from T_i x D sequences.

    EM never turns a zero probability into a non-zero one, so starting from a left-to-right
    transition matrix and a start in state 0 keeps that structure; it is checked after fitting.
    """
    seqs = _check_sequences(sequences, config.n_states, what)
    rng = np.random.default_rng(config.seed)
    q, m, d = config.n_states, config.n_mix, seqs[0].shape[1]
    weights, means, covars = _initial_emissions(seqs, config, rng)
    mean_len = float(np.mean([len(x) for x in seqs]))
    startprob = np.zeros(q)
    startprob[0] = 1.0
    model = _preinitialised_gmmhmm()(
        n_components=q,
        n_mix=m,
        covariance_type="full",
        min_covar=config.min_covar,
        covars_prior=config.min_covar * np.eye(d),
        covars_weight=-(d + 1.0),
        n_iter=config.n_iter,
        tol=config.tol,
        init_params="",
        params="stmcw",
        random_state=int(rng.integers(2**31 - 1)),
        implementation="scaling",
    )
    model.n_features = d
    model.startprob_ = startprob
    model.transmat_ = left_to_right_transmat(q, mean_len / q, config.max_jump)
    model.weights_ = weights
    model.means_ = means
    model.covars_ = covars
    if config.n_iter > 0:
        quiet = logging.getLogger("hmmlearn.base")  # "not converging" chatter at tol scale
        level = quiet.level
        quiet.setLevel(logging.ERROR)
        try:
            with np.errstate(divide="ignore", invalid="ignore"), _one_blas_thread():
                model.fit(np.concatenate(seqs), lengths=[len(x) for x in seqs])
        finally:
            quiet.setLevel(level)
    trained = _tidy(model, startprob)
    if not trained.is_left_to_right:  # pragma: no cover - guarded by EM's zero preservation
        raise RuntimeError("EM broke the left-to-right structure")
    return trained


def _preinitialised_gmmhmm() -> Any:
    """hmmlearn's GMMHMM whose fit() starts from the parameters already set.

    hmmlearn 0.3 runs k-means (11 times per model) in `_init` even when `init_params` is empty
    and then discards the result; skipping it is a third of the training time.
    """
    from hmmlearn.hmm import GMMHMM

    class PreinitialisedGMMHMM(GMMHMM):  # type: ignore[misc]  # hmmlearn has no type hints
        _densities: _Densities | None = None

        def _init(self, X: FloatArray, lengths: Any = None) -> None:
            self._check_and_set_n_features(X)
            self._init_covar_priors()
            self._fix_priors_shape()

        def _weighted_densities(self, X: FloatArray) -> FloatArray:
            cache = self._densities
            if cache is None or not cache.holds(self):
                cache = self._densities = _Densities(self.weights_, self.means_, self.covars_)
            return cache.of(X)

        # hmmlearn asks for one state's densities at a time, twice per sequence and iteration
        # (likelihood, then statistics), each with a Cholesky factorisation per component: two
        # thirds of the training time. Here they come from one pass over all components.
        def _compute_log_weighted_gaussian_densities(self, X: FloatArray, i: int) -> FloatArray:
            return self._weighted_densities(X)[:, i, :].copy()  # the caller normalises in place

        def _compute_log_likelihood(self, X: FloatArray) -> FloatArray:
            return logsumexp_last(self._weighted_densities(X))

    return PreinitialisedGMMHMM


class _Densities:
    """log(w) + log N(x; mu, S) of every state and mixture component for given parameters,
    the factorisations done once per EM iteration and the last sequence's values kept (each is
    asked for twice in a row)."""

    def __init__(self, weights: FloatArray, means: FloatArray, covars: FloatArray) -> None:
        self.params = (weights.copy(), means.copy(), covars.copy())
        q, m, d = means.shape
        chol = np.empty_like(covars)
        for s in range(q):
            for c in range(m):
                chol[s, c] = _cholesky(covars[s, c])
        self.inv_chol = np.linalg.inv(chol)
        with np.errstate(divide="ignore"):
            log_w = np.log(weights)
        logdet = 2.0 * np.log(np.diagonal(chol, axis1=-2, axis2=-1)).sum(axis=-1)
        self.const = log_w - 0.5 * (d * LOG_2PI + logdet)
        self.last: tuple[FloatArray, FloatArray] | None = None

    def holds(self, model: Any) -> bool:
        w, mu, cov = self.params
        return (
            np.array_equal(w, model.weights_)
            and np.array_equal(mu, model.means_)
            and np.array_equal(cov, model.covars_)
        )

    def of(self, X: FloatArray) -> FloatArray:
        """(T, D) -> (T, Q, M)."""
        if self.last is not None and self.last[0] is X:
            return self.last[1]
        mu = self.params[1]
        centred = X[:, None, None, :] - mu  # (T, Q, M, D)
        white = np.einsum("qmij,tqmj->tqmi", self.inv_chol, centred)
        out: FloatArray = self.const - 0.5 * np.einsum("tqmi,tqmi->tqm", white, white)
        self.last = (X, out)
        return out


def _cholesky(cov: FloatArray) -> FloatArray:
    """Lower Cholesky factor, with hmmlearn's fallback for a component stuck near singular."""
    try:
        return cast(FloatArray, np.linalg.cholesky(cov))
    except np.linalg.LinAlgError:
        try:
            return cast(FloatArray, np.linalg.cholesky(cov + 1e-7 * np.eye(len(cov))))
        except np.linalg.LinAlgError:
            raise InputError(
                "training diverged (a covariance is not positive-definite); give longer or more "
                "varied gestures"
            ) from None


def logsumexp_last(a: FloatArray) -> FloatArray:
    """log(sum(exp(a))) over the last axis; -inf where every term is -inf, without warnings."""
    top = a.max(axis=-1, keepdims=True)
    top = np.where(np.isfinite(top), top, 0.0)
    with np.errstate(divide="ignore", under="ignore"):
        return cast(np.ndarray, np.log(np.exp(a - top).sum(axis=-1)) + top[..., 0])


@contextmanager
def _one_blas_thread() -> Iterator[None]:
    """EM makes thousands of tiny LAPACK calls; with other processes on the machine, OpenBLAS
    threads waiting for each other turn 30 us calls into milliseconds. One thread is faster."""
    from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]

    with threadpool_limits(limits=1, user_api="blas"):
        yield


def _tidy(model: Any, startprob: FloatArray) -> GestureHMM:
    """Exact zeros and renormalised rows after EM (it leaves ~1e-16 residues)."""
    a = np.where(model.transmat_ < 1e-300, 0.0, model.transmat_)
    a = np.triu(a)
    rows = a.sum(axis=1, keepdims=True)
    a = np.where(rows > 0, a / np.where(rows > 0, rows, 1.0), np.eye(len(a)))
    w = np.clip(model.weights_, 0.0, None)
    w = w / w.sum(axis=1, keepdims=True)
    cov = 0.5 * (model.covars_ + np.swapaxes(model.covars_, -1, -2))
    if not (np.all(np.isfinite(model.means_)) and np.all(np.isfinite(cov))):
        raise InputError(
            "training diverged (non-finite parameters); the sequences are probably degenerate "
            "(constant or too few frames); give longer or more varied gestures"
        )
    return GestureHMM(startprob=startprob, transmat=a, weights=w, means=model.means_, covars=cov)


def train_models(
    data: Mapping[str, Sequence[ArrayLike]],
    config: TrainingConfig | None = None,
    *,
    actions: Sequence[str] | None = None,
    meta: Mapping[str, Any] | None = None,
    on_model: Callable[[str], None] | None = None,
    features: str = MOTION,
    floor_margin: float | None = FLOOR_MARGIN,
) -> GestureModels:
    """One HMM per action from `{action: [sequence (T_i, D), ...]}` in feature space `features`.

    `actions` fixes the order (default: the canonical grasp, tap, touch, then any others in the
    mapping's order). `on_model(action)` is called after each model, for progress bars. The
    models' `floor` is `floor_margin` below the worst fit of any training sequence (its
    per-frame log-likelihood under the best model); None: no floor.
    """
    cfg = config or TrainingConfig()
    if actions is None:
        actions = [a for a in ACTIONS if a in data] + [a for a in data if a not in ACTIONS]
    missing = [a for a in actions if a not in data]
    if missing:
        raise InputError(f"no training data for {', '.join(missing)}; have {', '.join(data)}")
    hmms = []
    for i, action in enumerate(actions):
        hmms.append(train_hmm(data[action], replace(cfg, seed=cfg.seed + i), what=action))
        if on_model is not None:
            on_model(action)
    info: dict[str, Any] = {
        "trained_with": "hmmlearn GMMHMM, EM from a uniform left-to-right segmentation",
        "config": {k: getattr(cfg, k) for k in cfg.__dataclass_fields__},
        "sequences": {a: len(data[a]) for a in actions},
        "frames": {a: int(sum(len(np.asarray(s)) for s in data[a])) for a in actions},
    }
    info.update(meta or {})
    models = GestureModels(actions=tuple(actions), hmms=tuple(hmms), meta=info, features=features)
    if floor_margin is None:
        return models
    worst = min(worst_fit(models, seqs) for seqs in data.values())
    return replace(models, floor=round(worst - floor_margin, 3))


def worst_fit(models: GestureModels, sequences: Sequence[ArrayLike]) -> float:
    """The lowest per-frame log-likelihood of these sequences under their best model."""
    from beyond_self.cognition.gestures.streaming import CompiledModels, recognize_sequence

    compiled = CompiledModels(models)
    return min(float(recognize_sequence(compiled, x).final.normalized.max()) for x in sequences)


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
