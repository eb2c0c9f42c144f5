"""The HMM class, the model file format, the MATLAB loader and training."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from beyond_self.cognition.gestures import (
    GestureHMM,
    GestureModels,
    TrainingConfig,
    load_matlab_models,
    load_models,
    save_models,
    train_hmm,
)
from beyond_self.core.errors import InputError

# these figures are computed again under a second OpenBLAS kernel (Makefile: numeric)
pytestmark = pytest.mark.numeric


def random_hmm(rng: np.random.Generator, q: int = 4, m: int = 2, d: int = 3) -> GestureHMM:
    a = np.triu(rng.random((q, q)))
    a /= a.sum(axis=1, keepdims=True)
    w = rng.random((q, m)) + 0.1
    w /= w.sum(axis=1, keepdims=True)
    root = rng.normal(size=(q, m, d, d)) * 0.3
    cov = root @ np.swapaxes(root, -1, -2) + 0.05 * np.eye(d)
    start = np.zeros(q)
    start[0] = 1.0
    return GestureHMM(start, a, w, rng.normal(size=(q, m, d)), cov)


def test_validation_rejects_bad_parameters() -> None:
    rng = np.random.default_rng(0)
    h = random_hmm(rng)
    good = {k: getattr(h, k) for k in ("startprob", "transmat", "weights", "means", "covars")}
    bad_cov = good["covars"].copy()
    bad_cov[0, 0] = -np.eye(3)
    cases = {
        "transmat": good["transmat"] * 2,
        "weights": good["weights"][:, :1],
        "means": good["means"][..., :2],
        "covars": bad_cov,
        "startprob": np.full(4, np.nan),
    }
    for key, value in cases.items():
        with pytest.raises(InputError):
            GestureHMM(**{**good, key: value})
    with pytest.raises(InputError, match="duplicate"):
        GestureModels(("tap", "tap"), (h, h))


def test_json_round_trip_is_bit_exact(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    models = GestureModels(
        ("grasp", "tap", "touch"),
        tuple(random_hmm(rng) for _ in range(3)),
        extra={"garbage": random_hmm(rng)},
        meta={"note": "test"},
    )
    path = save_models(models, tmp_path / "m.json")
    data = json.loads(path.read_text())
    assert data["format"] == "beyond-self/gesture-models" and data["version"] == 2
    assert data["features"] == "position" and data["floor"] is None
    back = load_models(path)
    assert back.actions == models.actions
    for a in (*models.actions, "garbage"):
        for key in ("startprob", "transmat", "weights", "means", "covars"):
            assert np.array_equal(getattr(back[a], key), getattr(models[a], key))
    assert load_models(path, include_garbage=True).actions[-1] == "garbage"
    data["version"] = 99
    (tmp_path / "v.json").write_text(json.dumps(data))
    with pytest.raises(InputError, match="version"):
        load_models(tmp_path / "v.json")
    with pytest.raises(InputError):
        load_models(tmp_path / "missing.json")
    (tmp_path / "x.pkl").write_text("")
    with pytest.raises(InputError, match="unknown model file type"):
        load_models(tmp_path / "x.pkl")


def test_feature_space_and_floor_travel_with_the_models(tmp_path: Path) -> None:
    rng = np.random.default_rng(2)
    hmms = tuple(random_hmm(rng, d=7) for _ in range(3))
    models = GestureModels(("grasp", "tap", "touch"), hmms, features="motion", floor=-24.5)
    back = load_models(save_models(models, tmp_path / "m.json"))
    assert (back.features, back.floor) == ("motion", -24.5)
    # a version-1 file (before feature spaces) holds "position" models with no floor
    data = json.loads(
        save_models(GestureModels(("grasp",), (random_hmm(rng),)), tmp_path / "p.json").read_text()
    )
    for key in ("features", "floor"):
        del data[key]
    data["version"] = 1
    (tmp_path / "v1.json").write_text(json.dumps(data))
    old = load_models(tmp_path / "v1.json")
    assert (old.features, old.floor) == ("position", None)
    with pytest.raises(InputError, match="'position' space has 3"):
        GestureModels(("grasp", "tap", "touch"), hmms)  # 7-D models in the 3-D space
    with pytest.raises(InputError, match="feature space"):
        GestureModels(("grasp",), (random_hmm(rng),), features="velocity")


def test_matlab_models_use_column_major_layout(shared_data: Path) -> None:
    path = shared_data / "saponaro2019/human_data/HMM_M3_Q6_mixsplit.mat"
    raw = scipy.io.loadmat(path)
    models = load_matlab_models(path)
    assert models.actions == ("grasp", "tap", "touch")
    for action, k in (("grasp", 3), ("tap", 1), ("touch", 4)):
        h = models[action]
        assert (h.n_states, h.n_mix, h.n_features) == (6, 3, 3)
        assert h.is_left_to_right
        mu, sigma = raw[f"hmm{k}_mu"], raw[f"hmm{k}_Sigma"]
        for q in range(6):
            for m in range(3):
                assert np.array_equal(h.means[q, m], mu[:, q, m])
                assert np.array_equal(h.covars[q, m], sigma[:, :, q, m])
        assert np.array_equal(h.weights, raw[f"hmm{k}_mixmat"])
        assert np.array_equal(h.transmat, raw[f"hmm{k}_trans"])
    assert "garbage" in models.extra
    assert np.array_equal(models.extra["garbage"].means[2, 1], raw["hmm0_mu"][:, 2, 1])
    one = load_models(path.with_name("HMM_M1_Q6_mixsplit.mat"), include_garbage=True)
    assert one.actions == ("grasp", "tap", "touch", "garbage")
    assert one["tap"].n_mix == 1
    raw1 = scipy.io.loadmat(path.with_name("HMM_M1_Q6_mixsplit.mat"))
    assert np.array_equal(one["tap"].means[4, 0], raw1["hmm1_mu"][:, 4])


def test_training_keeps_left_to_right_structure() -> None:
    rng = np.random.default_rng(2)
    # three-phase sequences: a left-to-right model should place its states in order
    seqs = []
    for _ in range(6):
        n = rng.integers(9, 14)
        seqs.append(np.concatenate([rng.normal(c, 0.1, size=(n, 3)) for c in (-2.0, 0.0, 2.0)]))
    h = train_hmm(seqs, TrainingConfig(n_states=3, n_mix=1, n_iter=5))
    assert h.is_left_to_right
    assert np.all(np.triu(h.transmat, k=2) == 0)  # max_jump 1: no skipping
    order = h.means[:, 0, 0]
    assert order[0] < order[1] < order[2]
    np.testing.assert_allclose(h.means[:, 0, 0], [-2, 0, 2], atol=0.2)
    with pytest.raises(InputError, match="too short"):
        train_hmm([np.zeros((2, 3))], TrainingConfig(n_states=3))
    with pytest.raises(InputError, match="NaN"):
        train_hmm([np.full((5, 3), np.nan)], TrainingConfig(n_states=3))
    with pytest.raises(InputError, match="features"):
        train_hmm([np.zeros((5, 3)), np.zeros((5, 2))], TrainingConfig(n_states=3))


def test_malformed_matlab_files_are_input_errors(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    h = random_hmm(rng, q=6, m=3)
    good = {
        "prior": h.startprob[:, None],
        "trans": h.transmat,
        "mu": h.means.transpose(2, 0, 1),  # D x Q x M
        "Sigma": h.covars.transpose(2, 3, 0, 1),  # D x D x Q x M
        "mixmat": h.weights,
    }
    arrays = {f"hmm{k}_{f}": v for k in (1, 3, 4) for f, v in good.items()}
    scipy.io.savemat(tmp_path / "ok.mat", arrays)
    loaded = load_matlab_models(tmp_path / "ok.mat")
    assert np.allclose(loaded["tap"].means, h.means)
    assert "garbage" not in loaded.extra
    broken = dict(arrays, hmm3_Sigma=good["Sigma"][:, :, :4])  # 4 states' covariances for 6
    scipy.io.savemat(tmp_path / "shape.mat", broken)
    with pytest.raises(InputError, match="hmm3"):
        load_matlab_models(tmp_path / "shape.mat")
    missing = {k: v for k, v in arrays.items() if k != "hmm4_trans"}
    scipy.io.savemat(tmp_path / "missing.mat", missing)
    with pytest.raises(InputError, match="hmm4_trans"):
        load_matlab_models(tmp_path / "missing.mat")
    (tmp_path / "junk.mat").write_bytes(b"not a mat file at all")
    with pytest.raises(InputError):
        load_matlab_models(tmp_path / "junk.mat")


def test_training_equals_hmmlearns_own_em() -> None:
    """Training computes every state's mixture densities in one pass (training._Densities) instead
    of hmmlearn's per-state Cholesky factorisations: the same EM, so the same parameters as
    hmmlearn's GMMHMM started from the same point, to rounding."""
    from unittest import mock

    from hmmlearn.hmm import GMMHMM

    from beyond_self.cognition.gestures import training

    def hmmlearn_em() -> type:
        class Plain(GMMHMM):  # type: ignore[misc]  # hmmlearn has no type hints
            def _init(self, X: np.ndarray, lengths: object = None) -> None:
                self._check_and_set_n_features(X)
                self._init_covar_priors()
                self._fix_priors_shape()

        return Plain

    rng = np.random.default_rng(5)
    seqs = [
        np.concatenate([rng.normal(c, 0.3, size=(int(rng.integers(8, 15)), 3)) for c in (-1, 1, 0)])
        for _ in range(12)
    ]
    config = TrainingConfig(n_states=4, n_mix=2, n_iter=8)
    ours = train_hmm(seqs, config)
    with mock.patch.object(training, "_preinitialised_gmmhmm", hmmlearn_em):
        reference = train_hmm(seqs, config)
    for name in ("transmat", "weights", "means", "covars"):
        np.testing.assert_allclose(
            getattr(ours, name), getattr(reference, name), rtol=1e-9, atol=1e-12, err_msg=name
        )
    # and the densities themselves, component by component, against hmmlearn's
    model = training._preinitialised_gmmhmm()(n_components=4, n_mix=2, covariance_type="full")
    model.weights_, model.means_, model.covars_ = ours.weights, ours.means, ours.covars
    x = seqs[0]
    for state in range(4):
        np.testing.assert_allclose(
            model._compute_log_weighted_gaussian_densities(x, state),
            GMMHMM._compute_log_weighted_gaussian_densities(model, x, state),
            rtol=1e-10,
        )
