"""Frame-by-frame recognition: P_HMM(A | G_1^t) updated at every frame t.

A scaled forward recursion per frame and model, with the log of each normaliser accumulated, so
log L(G_1^t | A) is a running sum and nothing under- or overflows however long the stream; a
frame whose every emission underflows is redone in the log domain. It agrees with hmmlearn's
`score` on every prefix (1e-6). All models are evaluated together: a frame's Gaussian log
densities are one matrix product of a quadratic feature vector with a precomputed table, so many
streams (`BatchRecognizer`) share the same few numpy calls. `StreamingRecognizer.push` takes a
frame; `recognize_sequence` a whole (T, D) array.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from beyond_self.cognition.gestures.hmm import (
    LOG_2PI,
    FloatArray,
    GestureModels,
    log_prior,
    logsumexp_last,
)
from beyond_self.core.errors import InputError


class CompiledModels:
    """A model set rearranged for fast evaluation; built once, shared by any number of streams.

    `CompiledModels.of(models)` is the one kept per model set: every recogniser given the set
    itself shares it (a fleet's process runs a tracker per robot on one model set). Its arrays
    are read-only, so no stream can change what the others read."""

    @staticmethod
    def of(models: GestureModels) -> CompiledModels:
        """The compiled form of `models`, built at the first call and kept while they live."""
        compiled = _COMPILED.get(models)
        if compiled is None:
            compiled = _COMPILED[models] = CompiledModels(models)
        return compiled

    def __init__(self, models: GestureModels) -> None:
        self.models = models
        self.actions = models.actions
        k = len(models.hmms)
        q = max(h.n_states for h in models.hmms)
        m = max(h.n_mix for h in models.hmms)
        d = models.n_features
        self.k, self.q, self.m, self.d = k, q, m, d
        iu, ju = np.triu_indices(d)
        self._iu, self._ju = iu, ju
        n_quad = len(iu)
        # log N(x; mu, S) + log w = phi(x) . coef + const, phi(x) = [x_i x_j (i<=j), x_i]
        coef = np.zeros((n_quad + d, k, q, m))
        const = np.full((k, q, m), -np.inf)
        start = np.zeros((k, q))
        trans = np.zeros((k, q, q))
        for a, h in enumerate(models.hmms):
            qa, ma = h.n_states, h.n_mix
            prec = np.linalg.inv(h.covars)  # (qa, ma, d, d)
            prec = 0.5 * (prec + np.swapaxes(prec, -1, -2))
            chol = np.linalg.cholesky(h.covars)
            logdet = 2.0 * np.log(np.diagonal(chol, axis1=-2, axis2=-1)).sum(axis=-1)
            quad = -0.5 * prec * (2.0 - np.eye(d))  # off-diagonals appear twice in x'Px
            coef[:n_quad, a, :qa, :ma] = np.moveaxis(quad[..., iu, ju], -1, 0)
            lin = np.einsum("qmij,qmj->qmi", prec, h.means)
            coef[n_quad:, a, :qa, :ma] = np.moveaxis(lin, -1, 0)
            mpm = np.einsum("qmi,qmi->qm", lin, h.means)
            with np.errstate(divide="ignore"):
                logw = np.log(h.weights)
            const[a, :qa, :ma] = logw - 0.5 * (d * LOG_2PI + logdet + mpm)
            start[a, :qa] = h.startprob
            trans[a, :qa, :qa] = h.transmat
        self.coef = coef.reshape(n_quad + d, k * q * m)
        self.const = const.reshape(k * q * m)
        self.start = start
        self.trans = trans
        with np.errstate(divide="ignore"):
            self.log_start = np.log(start)
            self.log_trans = np.log(trans)
        # one frame's evaluation on plain floats (StreamingRecognizer): the quadratic terms'
        # index pairs, and the table with the constant term folded in, lg = [phi(x), 1] @ table
        self.pairs = list(zip(iu.tolist(), ju.tolist(), strict=True))
        self.table = np.vstack([self.coef, self.const[None, :]])
        for array in (self.coef, self.const, self.start, self.trans, self.log_start,
                      self.log_trans, self.table, iu, ju):  # fmt: skip
            array.flags.writeable = False

    def phi(self, x: FloatArray) -> FloatArray:
        """Quadratic features (..., D) -> (..., D(D+1)/2 + D)."""
        return np.concatenate([x[..., self._iu] * x[..., self._ju], x], axis=-1)

    def log_gauss(self, x: FloatArray) -> FloatArray:
        """Weighted component log densities (..., D) -> (..., K, Q, M)."""
        out = self.phi(x) @ self.coef + self.const
        return cast(np.ndarray, out.reshape(*x.shape[:-1], self.k, self.q, self.m))

    def log_emission(self, x: FloatArray) -> FloatArray:
        """State log emission densities (..., D) -> (..., K, Q)."""
        return logsumexp_last(self.log_gauss(x))


_COMPILED: weakref.WeakKeyDictionary[GestureModels, CompiledModels] = weakref.WeakKeyDictionary()


def compiled(models: GestureModels | CompiledModels) -> CompiledModels:
    """`models` compiled: the model set's shared form (`CompiledModels.of`)."""
    return models if isinstance(models, CompiledModels) else CompiledModels.of(models)


def _check_frames(x: ArrayLike, d: int, n: int | None) -> FloatArray:
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError("frame is not numeric; valid: a sequence of feature values") from None
    want = (d,) if n is None else (n, d)
    if arr.shape != want:
        raise InputError(f"frame has shape {arr.shape}; valid: {want} feature values")
    if not np.all(np.isfinite(arr)):
        raise InputError("frame holds NaN or infinite values; valid: finite features")
    return arr


class _ForwardState:
    """Scaled forward variables of N streams x K models."""

    def __init__(self, compiled: CompiledModels, n: int, priors: ArrayLike | None) -> None:
        self.c = compiled
        self.n = n
        self.log_prior = log_prior(priors, compiled.k)
        self.alpha = np.zeros((n, compiled.k, compiled.q))
        self.loglik = np.zeros((n, compiled.k))
        self.t = np.zeros(n, dtype=np.int64)

    def reset(self, which: ArrayLike | None = None) -> None:
        idx = slice(None) if which is None else np.asarray(which)
        self.alpha[idx] = 0.0
        self.loglik[idx] = 0.0
        self.t[idx] = 0

    def step(
        self, x: FloatArray, idx: NDArray[np.int64] | slice, lg: FloatArray | None = None
    ) -> None:
        """Advance the streams `idx` by one frame each; x is (len(idx), D).

        `lg`: the frames' component log densities when already computed (whole sequences).
        """
        c = self.c
        if lg is None:
            lg = c.log_gauss(x)  # (n, K, Q, M)
        shift = lg.max(axis=(-2, -1))  # (n, K)
        shift = np.where(np.isfinite(shift), shift, 0.0)
        b = np.exp(lg - shift[..., None, None]).sum(axis=-1)  # (n, K, Q)
        alpha_prev = self.alpha[idx]
        first = self.t[idx] == 0
        pred = (alpha_prev[..., None, :] @ c.trans)[..., 0, :]  # (n, K, Q)
        if np.any(first):
            pred[first] = c.start
        alpha = pred * b
        scale = alpha.sum(axis=-1)  # (n, K)
        bad = ~(scale > 0)
        if np.any(bad):
            _log_domain_update(c, x, alpha, scale, shift, alpha_prev, first, bad)
        alpha /= scale[..., None]
        self.alpha[idx] = alpha
        self.loglik[idx] += np.log(scale) + shift
        self.t[idx] += 1


def _log_domain_update(
    c: CompiledModels,
    x: FloatArray,
    alpha: FloatArray,
    scale: FloatArray,
    shift: FloatArray,
    alpha_prev: FloatArray,
    first: NDArray[np.bool_],
    bad: NDArray[np.bool_],
) -> None:
    """Redo the (stream, model) pairs whose scaled emissions all underflowed, in logs."""
    for i, a in zip(*np.nonzero(bad), strict=True):
        le = c.log_emission(x[i])[a]  # (Q,)
        with np.errstate(divide="ignore"):
            if first[i]:
                lp = c.log_start[a]
            else:
                terms = np.log(alpha_prev[i, a])[:, None] + c.log_trans[a]
                top = terms.max(axis=0)
                safe = np.where(np.isfinite(top), top, 0.0)
                lp = np.log(np.exp(terms - safe).sum(axis=0)) + safe
        la = lp + le
        top_a = la.max()
        if not np.isfinite(top_a):  # impossible under this model: stays impossible
            alpha[i, a] = 1.0 / c.q
            scale[i, a] = 1.0
            shift[i, a] = -np.inf
            continue
        alpha[i, a] = np.exp(la - top_a)
        scale[i, a] = alpha[i, a].sum()
        shift[i, a] = top_a


@dataclass(frozen=True)
class FrameResult:
    """What the recogniser knows after frame t (1-based) of one gesture.

    loglik: log L(G_1^t | A) per action; normalized: loglik / t; posterior: P_HMM(A | G_1^t),
    all in the order of `actions`.
    """

    t: int
    actions: tuple[str, ...]
    loglik: FloatArray
    normalized: FloatArray
    posterior: FloatArray

    @property
    def best(self) -> str:
        """The most probable action so far."""
        return self.actions[int(np.argmax(self.posterior))]

    def to_dict(self) -> dict[str, object]:
        return {"t": self.t, "loglik": self.loglik.tolist(), "posterior": self.posterior.tolist()}


def _posterior(loglik: FloatArray, log_prior_: FloatArray) -> FloatArray:
    z = loglik + log_prior_
    top = np.max(z, axis=-1, keepdims=True)
    top = np.where(np.isfinite(top), top, 0.0)
    e = np.exp(z - top)
    total = e.sum(axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        post = e / total
    n = loglik.shape[-1]
    return cast(np.ndarray, np.where(total > 0, post, 1.0 / n))


def _posterior_1d(loglik: FloatArray, log_prior_: FloatArray) -> FloatArray:
    z = (loglik + log_prior_).tolist()  # K is small: plain floats beat numpy calls here
    top = max(z)
    if not math.isfinite(top):  # every model says impossible (or all +inf): no information
        return np.full(len(z), 1.0 / len(z))
    e = [math.exp(v - top) for v in z]
    total = sum(e)
    return np.array([v / total for v in e])


class StreamingRecognizer:
    """One observed gesture: push one feature frame at a time, read P_HMM(A | G_1^t) each time.

    `priors`: P(A) in the order of `models.actions` (equal when None). `reset()` starts a new
    gesture. Frames are feature vectors (see `cognition.gestures.features`): for the article's
    hand logs, the logged position times 0.001.

    The same recursion as `BatchRecognizer`, written for one stream with as few numpy calls per
    frame as possible (the per-call overhead, not arithmetic, is the cost at this size).
    """

    def __init__(
        self, models: GestureModels | CompiledModels, priors: ArrayLike | None = None
    ) -> None:
        c = compiled(models)
        self.compiled = c
        self.actions = c.actions
        self._log_prior = log_prior(priors, c.k)
        self._pairs = c.pairs
        self._table = c.table
        self._alpha = np.zeros((c.k, c.q))
        self._loglik = np.zeros(c.k)
        self._t = 0

    @property
    def t(self) -> int:
        """Frames seen since the last reset."""
        return self._t

    def reset(self) -> None:
        self._alpha = np.zeros_like(self._alpha)
        self._loglik = np.zeros_like(self._loglik)
        self._t = 0

    def push(self, frame: ArrayLike) -> FrameResult:
        c = self.compiled
        try:
            xs: list[float] = (
                frame.tolist() if isinstance(frame, np.ndarray) else list(frame)  # type: ignore[arg-type]
            )
        except TypeError:  # a scalar
            xs = []
        if len(xs) != c.d or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in xs):
            xs = _check_frames(frame, c.d, None).tolist()  # converts, or raises the InputError
        phi = [xs[i] * xs[j] for i, j in self._pairs]
        phi.extend(xs)
        phi.append(1.0)
        lg = (np.array(phi) @ self._table).reshape(c.k, c.q * c.m)
        shift = np.maximum.reduce(lg, axis=1)
        e = np.exp(lg - shift[:, None])
        b = np.add.reduce(e.reshape(c.k, c.q, c.m), axis=2) if c.m > 1 else e
        if self._t == 0:
            alpha = c.start * b
            prev = None
        else:
            prev = self._alpha
            alpha = (prev[:, None, :] @ c.trans).reshape(c.k, c.q) * b
        scale = np.add.reduce(alpha, axis=1)
        if (
            not np.minimum.reduce(scale) > 0
        ):  # every reachable state underflowed: redo those models in logs
            x = np.asarray(xs, dtype=np.float64)[None, :]
            first = np.array([self._t == 0])
            bad = ~(scale > 0)[None, :]
            prev_ = np.zeros((1, c.k, c.q)) if prev is None else prev[None]
            a2, s2, sh2 = alpha[None], scale[None], shift[None]
            _log_domain_update(c, x, a2, s2, sh2, prev_, first, bad)
        alpha /= scale[:, None]
        self._alpha = alpha
        self._loglik = loglik = self._loglik + (np.log(scale) + shift)
        self._t = t = self._t + 1
        return FrameResult(
            t=t,
            actions=self.actions,
            loglik=loglik,
            normalized=loglik / t,
            posterior=_posterior_1d(loglik, self._log_prior),
        )

    def push_many(self, frames: ArrayLike) -> list[FrameResult]:
        arr = np.asarray(frames, dtype=np.float64)
        if arr.ndim != 2:
            raise InputError(f"frames have shape {arr.shape}; valid: (T, D)")
        return [self.push(x) for x in arr]


@dataclass(frozen=True)
class BatchResult:
    """State of N concurrent streams after a batched update (arrays indexed by stream)."""

    t: NDArray[np.int64]  # (N,)
    loglik: FloatArray  # (N, K)
    posterior: FloatArray  # (N, K)

    @property
    def normalized(self) -> FloatArray:
        return self.loglik / np.maximum(self.t, 1)[:, None]


class BatchRecognizer:
    """Many concurrent gesture streams updated together, one frame per stream per call.

    `push(frames)` with frames (N, D) advances every stream; `push(frames, streams=idx)` only the
    listed streams (frames then (len(idx), D)), for streams that run at different rates.
    `reset(streams)` starts new gestures on some streams.
    """

    def __init__(
        self,
        models: GestureModels | CompiledModels,
        n_streams: int,
        priors: ArrayLike | None = None,
    ) -> None:
        if n_streams < 1:
            raise InputError(f"n_streams = {n_streams}; valid: at least 1")
        self.compiled = compiled(models)
        self.actions = self.compiled.actions
        self.n_streams = n_streams
        self._state = _ForwardState(self.compiled, n_streams, priors)

    def reset(self, streams: ArrayLike | None = None) -> None:
        self._state.reset(streams)

    def push(self, frames: ArrayLike, streams: ArrayLike | None = None) -> BatchResult:
        st = self._state
        if streams is None:
            x = _check_frames(frames, self.compiled.d, self.n_streams)
            st.step(x, slice(None))
        else:
            idx = np.asarray(streams, dtype=np.int64).ravel()
            if idx.size and (idx.min() < 0 or idx.max() >= self.n_streams):
                raise InputError(f"stream index out of range; valid: 0..{self.n_streams - 1}")
            if len(np.unique(idx)) != len(idx):
                raise InputError("a stream index appears twice; one frame per stream per push")
            x = _check_frames(frames, self.compiled.d, len(idx))
            st.step(x, idx)
        return self.state()

    def state(self) -> BatchResult:
        st = self._state
        return BatchResult(
            t=st.t.copy(), loglik=st.loglik.copy(), posterior=_posterior(st.loglik, st.log_prior)
        )


@dataclass(frozen=True)
class SequenceResult:
    """Per-frame recognition of a whole sequence: arrays (T, K), row t-1 after frame t."""

    actions: tuple[str, ...]
    loglik: FloatArray
    normalized: FloatArray
    posterior: FloatArray

    def __len__(self) -> int:
        return int(self.loglik.shape[0])

    def frame(self, t: int) -> FrameResult:
        """The result after frame t (1-based)."""
        if not 1 <= t <= len(self):
            raise InputError(f"frame {t} out of range; valid: 1..{len(self)}")
        i = t - 1
        return FrameResult(
            t=t,
            actions=self.actions,
            loglik=self.loglik[i],
            normalized=self.normalized[i],
            posterior=self.posterior[i],
        )

    @property
    def final(self) -> FrameResult:
        return self.frame(len(self))


def recognize_sequence(
    models: GestureModels | CompiledModels,
    features: ArrayLike,
    priors: ArrayLike | None = None,
) -> SequenceResult:
    """Run the streaming recogniser over a whole (T, D) feature array, keeping every frame."""
    c = compiled(models)
    x = np.asarray(features, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != c.d or x.shape[0] < 1:
        raise InputError(f"features have shape {x.shape}; valid: (T, {c.d}) with T >= 1")
    if not np.all(np.isfinite(x)):
        raise InputError("features hold NaN or infinite values; valid: finite numbers")
    state = _ForwardState(c, 1, priors)
    out = np.empty((len(x), c.k))
    lg = c.log_gauss(x)  # all frames at once; only the recursion is sequential
    for t in range(len(x)):
        state.step(x[t : t + 1], slice(None), lg[t : t + 1])
        out[t] = state.loglik[0]
    steps = np.arange(1, len(x) + 1)[:, None]
    return SequenceResult(
        actions=c.actions,
        loglik=out,
        normalized=out / steps,
        posterior=_posterior(out, state.log_prior),
    )
