"""What every plot of the science shares: matplotlib without a display (Agg), and the article's
notation written as mathematics (matplotlib's mathtext), so a figure can go into a paper as it is:
P_HMM(A | G_1^t) set as $P_{\\mathrm{HMM}}(A \\mid G_1^t)$, never as the raw characters."""

from __future__ import annotations

from pathlib import Path
from typing import Any

# fragments of mathtext (without the $), to build labels from
HMM = r"P_{\mathrm{HMM}}"  # the gesture recogniser's belief
COMB = r"P_{\mathrm{comb}}"  # the network's belief fused with the gesture's
OBS = r"X_{\mathrm{obs}}"  # what is observed of the object and the effects
GESTURE = r"G_1^t"  # the gesture's frames up to t
NORM_LOGLIK = r"\frac{1}{t}\,\log L(G_1^t \mid A)"  # the article's per-frame log-likelihood


def math(text: str) -> str:
    """`text` as mathtext (between $)."""
    return f"${text}$"


def word(text: str) -> str:
    """A word or a value set upright inside mathematics (spaces kept)."""
    return r"\mathrm{" + text.replace(" ", r"\ ") + "}"


def p_hmm(of: str = "A", given: str = GESTURE) -> str:
    """$P_HMM(of | given)$."""
    return math(rf"{HMM}({of} \mid {given})")


def p_comb(of: str, given: str) -> str:
    """$P_comb(of | given)$."""
    return math(rf"{COMB}({of} \mid {given})")


def pyplot() -> Any:
    """matplotlib.pyplot on the Agg backend (no display needed, same pixels everywhere)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Any, path: str | Path, dpi: int = 120) -> Path:
    """Write a figure as a PNG (creating its folder) and free it: a long run makes many."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi)
    pyplot().close(fig)
    return out
