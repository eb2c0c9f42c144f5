"""HMM training time: ours (one pass of mixture densities per sequence and EM iteration,
cognition/gestures/training.py) against hmmlearn's own GMMHMM EM started from the same point, in the
same run, on the same synthetic gestures; and how far apart the trained parameters are.

    .venv/bin/python bench/training.py [--repeat N]

Ends with one line of JSON.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any
from unittest import mock

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from beyond_self.cognition.gestures import training
from beyond_self.cognition.gestures.datasets import synthetic_gestures


def hmmlearn_em() -> type:
    """hmmlearn's GMMHMM, started from the parameters train_hmm sets (as ours is)."""
    from hmmlearn.hmm import GMMHMM

    class Plain(GMMHMM):  # type: ignore[misc]  # hmmlearn has no type hints
        def _init(self, X: Any, lengths: Any = None) -> None:
            self._check_and_set_n_features(X)
            self._init_covar_priors()
            self._fix_priors_shape()

    return Plain


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=3, help="trainings of each (default 3)")
    args = parser.parse_args()
    seqs = [g.features for g in synthetic_gestures(60, seed=0) if g.action == "grasp"]
    config = training.TrainingConfig(n_iter=10)
    training.train_hmm(seqs[:5], training.TrainingConfig(n_iter=1))  # imports, outside the timing
    ours_s, ref_s = [], []
    for _ in range(args.repeat):
        t0 = time.process_time()
        ours = training.train_hmm(seqs, config)
        ours_s.append(time.process_time() - t0)
        with mock.patch.object(training, "_preinitialised_gmmhmm", hmmlearn_em):
            t0 = time.process_time()
            ref = training.train_hmm(seqs, config)
            ref_s.append(time.process_time() - t0)
    diff = max(
        float(np.max(np.abs(getattr(ours, f) - getattr(ref, f))))
        for f in ("transmat", "weights", "means", "covars")
    )
    result = {
        "sequences": len(seqs),
        "em_iterations": config.n_iter,
        "ours_cpu_s": round(min(ours_s), 3),
        "hmmlearn_cpu_s": round(min(ref_s), 3),
        "speedup_vs_hmmlearn": round(min(ref_s) / min(ours_s), 2),
        "max_abs_parameter_difference": diff,
    }
    print(
        f"one model, {len(seqs)} sequences, {config.n_iter} EM iterations: ours "
        f"{result['ours_cpu_s']} CPU-s, hmmlearn {result['hmmlearn_cpu_s']} CPU-s "
        f"({result['speedup_vs_hmmlearn']}x); parameters differ by at most {diff:.1e}"
    )
    print(json.dumps(result))


if __name__ == "__main__":
    main()
