"""Training the gesture models: one left-to-right GMM-HMM per action, by hmmlearn's EM.

Each model starts from a uniform split of its sequences into states (k-means within each) and a
left-to-right transition matrix, which EM keeps (it never makes a zero probability non-zero).
The model set's floor is set below the worst fit of any training gesture (`worst_fit`).
hmmlearn and SciPy are imported only when a model is trained.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from typing import Any, cast

import numpy as np
from numpy.typing import ArrayLike

from beyond_self.cognition.gestures.features import MOTION
from beyond_self.cognition.gestures.hmm import (
    LOG_2PI,
    FloatArray,
    GestureHMM,
    GestureModels,
    logsumexp_last,
)
from beyond_self.cognition.gestures.streaming import CompiledModels, recognize_sequence
from beyond_self.cognition.variables import ACTIONS
from beyond_self.core.errors import InputError

# nats per frame below the worst-fitting training gesture: people are sloppier than a simulator
FLOOR_MARGIN = 15.0


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
    compiled = CompiledModels(models)
    return min(float(recognize_sequence(compiled, x).final.normalized.max()) for x in sequences)
