"""The streaming recogniser against hmmlearn, an independent scipy forward pass, and the article."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io
from scipy.special import logsumexp
from scipy.stats import multivariate_normal
from test_gesture_models import random_hmm

from beyond_self.cognition.gestures.features import extract_features
from beyond_self.cognition.gestures.hmm import GestureHMM, GestureModels
from beyond_self.cognition.gestures.logs import read_hand_log
from beyond_self.cognition.gestures.matlab import load_matlab_models
from beyond_self.cognition.gestures.streaming import (
    BatchRecognizer,
    CompiledModels,
    StreamingRecognizer,
    recognize_sequence,
)
from beyond_self.core.errors import InputError


def hmmlearn_prefix_scores(
    models: GestureModels, x: np.ndarray, lengths: list[int] | None = None
) -> np.ndarray:
    refs = [h.to_hmmlearn() for h in models.hmms]
    ts = lengths or range(1, len(x) + 1)
    return np.array([[r.score(x[:t]) for r in refs] for t in ts])


def mixed_models(seed: int) -> GestureModels:
    rng = np.random.default_rng(seed)
    # different sizes exercise the padding of states and mixture components
    hmms = (random_hmm(rng, 4, 2), random_hmm(rng, 6, 3), random_hmm(rng, 3, 1))
    return GestureModels(("grasp", "tap", "touch"), hmms)


def test_every_prefix_matches_hmmlearn_score() -> None:
    models = mixed_models(3)
    rng = np.random.default_rng(4)
    x = rng.normal(size=(40, 3)) * 1.5
    expected = hmmlearn_prefix_scores(models, x)
    rec = StreamingRecognizer(models)
    got = np.array([rec.push(f).loglik for f in x])
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-6)
    np.testing.assert_allclose(recognize_sequence(models, x).loglik, expected, rtol=0, atol=1e-6)


def test_reference_models_match_hmmlearn(shared_data: Path) -> None:
    models = load_matlab_models(shared_data / "saponaro2019/human_data/HMM_M3_Q6_mixsplit.mat")
    log = read_hand_log(shared_data / "saponaro2019/human_data/norobotview_tap_notable_seated_2")
    x = extract_features(log.frames(160, 375), scale=0.001)
    res = recognize_sequence(models.including("garbage"), x)
    lengths = [*range(1, len(x), 9), len(x)]  # hmmlearn is slow: a spread of prefixes
    expected = hmmlearn_prefix_scores(models.including("garbage"), x, lengths)
    np.testing.assert_allclose(res.loglik[np.array(lengths) - 1], expected, rtol=0, atol=1e-6)


@pytest.mark.numeric  # computed again under a second OpenBLAS kernel
def test_underflowing_emissions_fall_back_to_logs() -> None:
    # state 0 (the only reachable one at t=1) is tight and far away; state 1 sits on the data,
    # so scaled emissions of state 0 underflow to exactly 0
    cov = np.stack([np.eye(3) * 1e-4, np.eye(3)])[:, None]
    h = GestureHMM(
        startprob=[1.0, 0.0],
        transmat=[[0.9, 0.1], [0.0, 1.0]],
        weights=[[1.0], [1.0]],
        means=[[[5.0, 0.0, 0.0]], [[0.0, 0.0, 0.0]]],
        covars=cov,
    )
    models = GestureModels(("grasp", "tap"), (h, random_hmm(np.random.default_rng(5), 2, 1)))
    x = np.zeros((6, 3))
    expected = hmmlearn_prefix_scores(models, x)
    assert expected[0, 0] < -1e5  # really out of the exponent's range
    rec = StreamingRecognizer(models)
    got = np.array([rec.push(f).loglik for f in x])
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    batch = BatchRecognizer(models, 2)
    for f in x:
        state = batch.push(np.stack([f, f + 0.1]))
    np.testing.assert_allclose(state.loglik[0], expected[-1], rtol=1e-12)


@pytest.mark.numeric  # computed again under a second OpenBLAS kernel
def test_long_streams_stay_finite() -> None:
    models = mixed_models(6)
    rng = np.random.default_rng(7)
    x = rng.normal(size=(3000, 3))
    res = recognize_sequence(models, x)
    assert np.all(np.isfinite(res.loglik)) and np.all(np.isfinite(res.posterior))
    assert res.loglik[-1].max() < -3000  # far below exp()'s range: log-scale accumulation
    expected = [h.to_hmmlearn().score(x) for h in models.hmms]
    np.testing.assert_allclose(res.loglik[-1], expected, rtol=1e-10)


@pytest.mark.numeric  # computed again under a second OpenBLAS kernel
def test_batch_matches_single_streams_at_different_offsets() -> None:
    models = mixed_models(8)
    rng = np.random.default_rng(9)
    xs = [rng.normal(size=(25, 3)) for _ in range(4)]
    single = [recognize_sequence(models, x) for x in xs]
    batch = BatchRecognizer(models, 4, priors=None)
    # streams 2 and 3 start 5 frames later: updated only when they have a frame
    for t in range(25):
        batch.push(np.stack([xs[0][t], xs[1][t]]), streams=[0, 1])
        if t >= 5:
            state = batch.push(np.stack([xs[2][t - 5], xs[3][t - 5]]), streams=[2, 3])
    assert state.t.tolist() == [25, 25, 20, 20]
    for i, n in enumerate((25, 25, 20, 20)):
        np.testing.assert_allclose(state.loglik[i], single[i].loglik[n - 1], atol=1e-9)
        np.testing.assert_allclose(state.posterior[i], single[i].posterior[n - 1], atol=1e-9)
    batch.reset([0])
    assert batch.state().t.tolist() == [0, 25, 20, 20]
    with pytest.raises(InputError):
        batch.push(np.zeros((1, 3)), streams=[4])
    with pytest.raises(InputError):
        batch.push(np.zeros((2, 3)), streams=[1, 1])


def test_streams_of_one_model_set_share_its_tables_and_keep_their_own_state() -> None:
    """A fleet's process runs a recogniser per robot on one model set: the compiled tables are
    built once and read-only, and robots pushed in turn get exactly what each gets alone (the
    same arithmetic on the same tables: a shared table must not move a single bit)."""
    models = mixed_models(10)
    robots = [StreamingRecognizer(models) for _ in range(3)]
    assert robots[0].compiled is robots[1].compiled is CompiledModels.of(models)
    assert CompiledModels.of(mixed_models(10)) is not robots[0].compiled  # per model set
    with pytest.raises(ValueError):
        robots[0].compiled.trans[0, 0, 0] = 0.5
    rng = np.random.default_rng(11)
    xs = [rng.normal(size=(30, 3)) for _ in robots]
    together = [[r.push(x[t]) for t in range(30)][-1] for r, x in zip(robots, xs, strict=True)]
    for rec in robots:
        rec.reset()
    for t in range(30):  # frame by frame, robot after robot
        turn = [r.push(x[t]) for r, x in zip(robots, xs, strict=True)]
    for alone, interleaved in zip(together, turn, strict=True):
        assert np.array_equal(alone.loglik, interleaved.loglik)
        assert np.array_equal(alone.posterior, interleaved.posterior)
    assert not np.array_equal(turn[0].loglik, turn[1].loglik)  # the robots are told apart


@pytest.mark.numeric  # computed again under a second OpenBLAS kernel
def test_posterior_uses_priors_and_normalised_is_per_frame() -> None:
    models = mixed_models(10)
    x = np.random.default_rng(11).normal(size=(8, 3))
    priors = np.array([0.7, 0.2, 0.1])
    rec = StreamingRecognizer(models, priors=priors)
    for f in x:
        r = rec.push(f)
    w = np.exp(r.loglik - r.loglik.max()) * priors
    np.testing.assert_allclose(r.posterior, w / w.sum(), atol=1e-12)
    np.testing.assert_allclose(r.normalized, r.loglik / 8)
    assert r.t == 8 and r.best == models.actions[int(np.argmax(w))]
    rec.reset()
    assert rec.t == 0
    assert rec.push(x[0]).t == 1
    with pytest.raises(InputError):
        rec.push([0.0, 1.0])
    with pytest.raises(InputError):
        rec.push([0.0, np.nan, 1.0])
    with pytest.raises(InputError):
        rec.push(["a", "b", "c"])
    with pytest.raises(InputError):
        StreamingRecognizer(models, priors=[1.0, -1.0, 1.0])


def _scipy_forward(mat: dict[str, np.ndarray], k: int, x: np.ndarray) -> np.ndarray:
    """log L(G_1^t | model k) for every t: the article's arrays indexed column-major directly."""
    prior = mat[f"hmm{k}_prior"].ravel().astype(float)
    trans = mat[f"hmm{k}_trans"]
    mu, sigma, mix = mat[f"hmm{k}_mu"], mat[f"hmm{k}_Sigma"], mat[f"hmm{k}_mixmat"]
    q_n, m_n = mix.shape
    logb = np.empty((len(x), q_n))
    for q in range(q_n):
        comps = [
            np.log(mix[q, m]) + multivariate_normal(mu[:, q, m], sigma[:, :, q, m]).logpdf(x)
            for m in range(m_n)
        ]
        logb[:, q] = logsumexp(np.stack(comps), axis=0)
    with np.errstate(divide="ignore"):
        log_a, log_alpha = np.log(trans), np.log(prior) + logb[0]
    out = [logsumexp(log_alpha)]
    for t in range(1, len(x)):
        log_alpha = logsumexp(log_alpha[:, None] + log_a, axis=0) + logb[t]
        out.append(logsumexp(log_alpha))
    return np.array(out)


@pytest.mark.numeric  # computed again under a second OpenBLAS kernel
def test_article_tap_is_recognised_before_it_ends(shared_data: Path) -> None:
    """Effect anticipation input: tap_notable_seated_1, frames 121-214, mm / 1000, M3 models."""
    folder = shared_data / "saponaro2019/human_data"
    mat = scipy.io.loadmat(folder / "HMM_M3_Q6_mixsplit.mat")
    x = read_hand_log(folder / "tap_notable_seated_1").frames(121, 214) * 0.001
    assert len(x) == 94
    expected = np.stack([_scipy_forward(mat, k, x) for k in (3, 1, 4)], axis=1)

    models = load_matlab_models(folder / "HMM_M3_Q6_mixsplit.mat")
    rec = StreamingRecognizer(models)
    frames = [rec.push(f) for f in x]
    got = np.array([r.loglik for r in frames])
    np.testing.assert_allclose(got[-1], expected[-1], rtol=0, atol=1e-6)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-6)

    # the article's result (recording numbering): tap becomes and stays the most probable
    # action from frame 175 on
    best = [models.actions[int(np.argmax(r.posterior))] for r in frames]
    from_frame = 121 + max(i for i, b in enumerate(best) if b != "tap") + 1
    assert from_frame == 175 and best[175 - 121 :] == ["tap"] * (214 - 175 + 1)
    tap = np.array([r.posterior[models.actions.index("tap")] for r in frames])
    settled = np.flatnonzero(tap < 0.99)[-1] + 2  # first t from which P(tap) stays >= 0.99
    assert settled < 94, "the posterior must settle on tap before the gesture ends"
    assert frames[-1].best == "tap"
    assert tap[:10].max() < 0.5  # and it is not tap from the start: it is learned on the way
