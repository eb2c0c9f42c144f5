"""Loader for the article's reference gesture HMMs (`HMM_M{1,3}_Q6_mixsplit.mat`).

The files were written by Kevin Murphy's BNT/HMM toolbox: per model `hmm<k>_prior` (Q x 1),
`hmm<k>_trans` (Q x Q, row = from-state), `hmm<k>_mu` (D x Q x M), `hmm<k>_Sigma`
(D x D x Q x M), `hmm<k>_mixmat` (Q x M). MATLAB drops trailing singleton dimensions, so the
one-mixture file stores mu as D x Q and Sigma as D x D x Q. Numbering, from the article's code:
hmm1 = tap, hmm3 = grasp, hmm4 = push (the article's stand-in for touch), hmm0 = garbage.
Observations are the hand logs times 0.001 (see `cognition.gestures.features`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from beyond_self.cognition.gestures.features import POSITION
from beyond_self.cognition.gestures.hmm import GestureHMM, GestureModels
from beyond_self.core.errors import InputError

# action -> model number in the MATLAB file, in the canonical action order
REFERENCE_NUMBERS: dict[str, int] = {"grasp": 3, "tap": 1, "touch": 4}
GARBAGE_NUMBER = 0


def _model(mat: dict[str, np.ndarray], k: int, path: Path) -> GestureHMM:
    keys = [f"hmm{k}_{f}" for f in ("prior", "trans", "mu", "Sigma", "mixmat")]
    missing = [key for key in keys if key not in mat]
    if missing:
        raise InputError(f"{path} lacks {', '.join(missing)}; not an article gesture-model file")
    prior, trans, mu, sigma, mixmat = (np.asarray(mat[key], dtype=np.float64) for key in keys)
    q = prior.size
    mixmat = mixmat.reshape(q, -1)
    m = mixmat.shape[1]
    d = mu.shape[0] if mu.ndim >= 1 else 0
    try:
        mu = mu.reshape(d, q, m, order="F")
        sigma = sigma.reshape(d, d, q, m, order="F")
    except ValueError:
        raise InputError(
            f"{path}: hmm{k} arrays have inconsistent shapes (mu {mat[keys[2]].shape}, "
            f"Sigma {mat[keys[3]].shape}, mixmat {mat[keys[4]].shape})"
        ) from None
    return GestureHMM(
        startprob=prior.ravel(),
        transmat=trans,
        weights=mixmat,
        means=mu.transpose(1, 2, 0),  # mu[:, q, m] -> means[q, m, :]
        covars=sigma.transpose(2, 3, 0, 1),  # Sigma[:, :, q, m] -> covars[q, m, :, :]
    )


def load_matlab_models(path: str | Path, *, include_garbage: bool = False) -> GestureModels:
    """The reference models as (grasp, tap, touch); the garbage model rides in `extra`.

    With `include_garbage` it becomes a fourth class ("garbage") of the posterior.
    """
    from scipy.io import loadmat

    p = Path(path)
    try:
        mat = loadmat(p)
    except Exception as exc:  # scipy raises anything from IndexError to MatReadError on junk
        if isinstance(exc, InputError):
            raise
        raise InputError(
            f"{p} is not a readable MATLAB v5 file ({exc.__class__.__name__})"
        ) from None
    actions = tuple(REFERENCE_NUMBERS)
    hmms = tuple(_model(mat, REFERENCE_NUMBERS[a], p) for a in actions)
    extra = {}
    if f"hmm{GARBAGE_NUMBER}_prior" in mat:
        extra["garbage"] = _model(mat, GARBAGE_NUMBER, p)
    models = GestureModels(
        actions=actions,
        hmms=hmms,
        extra=extra,
        meta={
            "source": str(p.name),
            "origin": "gsaponaro/tcds-gestures (BNT HMM toolbox, CR-HRI 2013 models)",
            "numbering": {
                **{a: f"hmm{n}" for a, n in REFERENCE_NUMBERS.items()},
                "garbage": "hmm0",
            },
            "touch_is": "push (hmm4), the article's stand-in for touch",
        },
        features=POSITION,  # the hand logs times 0.001, frame by frame
    )
    return models.including("garbage") if include_garbage and "garbage" in extra else models
