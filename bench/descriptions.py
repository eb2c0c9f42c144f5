"""Exact N-best over the whole grammar vs brute force vs the article's sample-and-rescore.

For the same seeded word probabilities, in one run:
- ours: the exact 10-best over all 9,331,200 sentences (`nbest_exact`), without enumerating them;
- reference: brute force, every sentence scored with numpy, two ways: the textbook one (the full
  array of 9.3M scores, then a partial sort) and the fastest I could make honestly (cache-sized
  chunks, only each prefix's best score kept, then the few prefixes that can win re-scored);
  ratios are against the fastest;
- the article's method: draw 10,000 sentences like HSGen, drop repeats, re-score, take the top 10
  (and, when ../shared/data is present, re-scoring the article's own list of 9,941 sentences).
Asserts the exact list equals the brute force's and is never worse than sampling's best.
Goals: exact 10-best under 1 ms and at least 200x faster than the brute force.
The last line printed is one JSON object with every figure.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from beyond_self.cognition.descriptions import (
    SentenceSpace,
    brute_force_nbest,
    brute_force_nbest_plain,
    brute_force_scores,
    nbest_exact,
    nbest_from_file,
    nbest_sampled,
)
from beyond_self.cognition.grammar import DEFAULT_GRAMMAR
from beyond_self.cognition.paths import shared_data_dir

SEED = 2019
N = 10
COLOUR = r"\b(green|yellow|blue)\b"


def timed(fn: Callable[[], Any], repeats: int) -> tuple[Any, list[float]]:
    """Result of the last call and every call's wall time in seconds."""
    times = []
    result = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return result, times


def main() -> None:
    # no options: --help says what it measures and exits
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.parse_args()
    rng = np.random.default_rng(SEED)
    probs = {
        w: float(p)
        for w, p in zip(DEFAULT_GRAMMAR.vocabulary, rng.uniform(0.01, 0.99, 49), strict=True)
    }
    t0 = time.perf_counter()
    space = SentenceSpace.of(DEFAULT_GRAMMAR)
    compile_s = time.perf_counter() - t0
    print(f"grammar: {space.count:,} sentences; compiled once in {compile_s * 1e3:.1f} ms")

    nbest_exact(probs, N)  # warm caches (block strings) before timing
    exact, exact_t = timed(lambda: nbest_exact(probs, N), 500)
    exact_ms = statistics.median(exact_t) * 1e3
    exact_min_ms = min(exact_t) * 1e3

    _, score_t = timed(lambda: brute_force_scores(probs), 5)
    plain, plain_t = timed(lambda: brute_force_nbest_plain(probs, N), 5)
    brute, brute_t = timed(lambda: brute_force_nbest(probs, N), 5)
    brute_ms = min(brute_t) * 1e3
    plain_ms = min(plain_t) * 1e3
    score_all_ms = min(score_t) * 1e3
    assert exact == brute == plain, "exact search differs from brute force"

    sampled, sample_t = timed(lambda: nbest_sampled(probs, 10_000, SEED, N), 20)
    sample_ms = statistics.median(sample_t) * 1e3
    assert exact[0].score >= sampled[0].score, "exact best is worse than a sampled one"

    required, require_t = timed(lambda: nbest_exact(probs, N, require=COLOUR), 100)
    require_ms = statistics.median(require_t) * 1e3
    legacy, legacy_t = timed(lambda: nbest_exact(probs, N, legacy_offset=True), 200)
    assert legacy == brute_force_nbest(probs, N, legacy_offset=True)

    file_ms = None
    file_best = None
    data = shared_data_dir()
    if data is not None and (data / "saponaro2019" / "sentence_10000samples_uniq.txt").exists():
        path = data / "saponaro2019" / "sentence_10000samples_uniq.txt"
        listed, file_t = timed(lambda: nbest_from_file(path, probs, N), 5)
        file_ms = statistics.median(file_t[1:]) * 1e3  # the first call builds the parse tables
        file_best = listed[0].score
        assert exact[0].score >= listed[0].score

    speedup = brute_ms / exact_ms
    print(f"\n{'method':50s} {'time':>11s} {'vs exact':>9s} {'best score':>11s}")
    rows = [
        ("exact 10-best, whole grammar (ours, median)", exact_ms, exact[0].score),
        ("brute force, chunked (fastest; best of 5)", brute_ms, brute[0].score),
        ("brute force, full score array + top 10 (best of 5)", plain_ms, plain[0].score),
        ("  of which scoring every sentence", score_all_ms, None),
        ("sample 10,000 like HSGen + re-score (median)", sample_ms, sampled[0].score),
    ]
    if file_ms is not None:
        rows.append(("re-score the article's 9,941-sentence list", file_ms, file_best))
    rows += [
        ("exact 10-best with a colour word (--require)", require_ms, required[0].score),
        ("exact 10-best, legacy offset", statistics.median(legacy_t) * 1e3, legacy[0].score),
    ]
    for name, ms, best in rows:
        shown = "" if best is None else f"{best:.5f}"
        print(f"{name:50s} {ms:9.3f} ms {ms / exact_ms:8.1f}x {shown:>11s}")
    print(
        f"\nexact == both brute forces: yes; exact is {speedup:.0f}x faster than the fastest"
        f" brute force and {plain_ms / exact_ms:.0f}x faster than the textbook one"
    )
    print(f"sampling's best is {exact[0].score - sampled[0].score:.5f} below the true best")
    print("10-best (exact):")
    for item in exact:
        print(f"  {item.score:.5f}  {item.sentence}")
    goals = {"exact_under_1ms": exact_ms < 1.0, "speedup_at_least_200x": speedup >= 200}
    print(f"goals: {goals}")
    figures = {
        "bench": "descriptions",
        "seed": SEED,
        "n": N,
        "sentences": space.count,
        "compile_ms": round(compile_s * 1e3, 3),
        "exact_ms_median": round(exact_ms, 4),
        "exact_ms_min": round(exact_min_ms, 4),
        "brute_force_ms": round(brute_ms, 2),
        "brute_force_plain_ms": round(plain_ms, 2),
        "brute_force_score_all_ms": round(score_all_ms, 2),
        "speedup_vs_brute_force": round(speedup, 1),
        "speedup_vs_plain_brute_force": round(plain_ms / exact_ms, 1),
        "sampled_10000_ms": round(sample_ms, 3),
        "article_list_rescore_ms": None if file_ms is None else round(file_ms, 3),
        "exact_require_colour_ms": round(require_ms, 4),
        "exact_best": exact[0].score,
        "sampled_best": sampled[0].score,
        "article_list_best": file_best,
        "exact_equals_brute_force": True,
        **goals,
    }
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
