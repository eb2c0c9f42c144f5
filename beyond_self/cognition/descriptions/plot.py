"""A picture of an N-best list for reports: one horizontal bar per sentence, best at the top."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

from beyond_self.cognition.descriptions.space import ScoredSentence
from beyond_self.core.errors import InputError


def plot_nbest(items: Sequence[ScoredSentence], path: str | Path, title: str) -> Path:
    """Write a PNG of the scores with the sentences as labels; −inf scores are marked, not drawn."""
    from beyond_self.cognition.plotting import pyplot

    plt = pyplot()
    if not items:
        raise InputError("cannot plot an empty N-best list; give at least one sentence")
    path = Path(path)
    scores = [it.score for it in items]
    finite = [s for s in scores if math.isfinite(s)]
    lo, hi = (min(finite), max(finite)) if finite else (-1.0, 0.0)
    span = max(hi - lo, 1e-3)
    # the scores of an N-best list are close together: bars grow from just left of the worst
    # one, so their differences are visible; the value is printed at the end of each bar
    left, right = lo - 0.6 * span, hi + 0.3 * span
    fig, ax = plt.subplots(figsize=(10, 0.9 + 0.38 * len(items)))
    ys = list(range(len(items)))
    widths = [s - left if math.isfinite(s) else 0.0 for s in scores]
    ax.barh(ys, widths, left=left, color="tab:blue", height=0.6)
    for y, s in zip(ys, scores, strict=True):
        label = f" {s:.5f}" if math.isfinite(s) else " −inf (a word has P = 0)"
        ax.text(s if math.isfinite(s) else left, y, label, va="center", ha="left", fontsize=8)
    ax.set_yticks(ys)
    ax.set_yticklabels([it.sentence for it in items], fontsize=9)
    ax.invert_yaxis()  # best first, at the top
    ax.set_xlim(left, right)
    ax.set_xlabel(
        r"score $= \frac{1}{L}\sum_i \log P(w_i)$, the mean over the sentence's $L$ words "
        "(higher is better)"
    )
    ax.set_title(title)
    ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
