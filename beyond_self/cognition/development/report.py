"""The outputs of a learning run: learning.md for people, results.json for programs, PNG plots.

results.json (format `beyond-self/learning-results`, version 1) holds everything the report
shows: the configuration, the network's affordance arcs, the observation noise actually drawn,
the main condition (label summary, κ, accuracy and confusion of every source, rows = true action,
columns = predicted, in `actions` order), the acceptance checks and every ablation condition.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from beyond_self.cognition import plotting
from beyond_self.cognition.development.learning import (
    SOURCE_NAMES,
    SOURCES,
    Condition,
    LearningResults,
)

RESULTS_FILE = "results.json"
REPORT_FILE = "learning.md"
CONFUSIONS_PNG = "confusions.png"
CURVE_PNG = "accuracy_vs_demonstrations.png"
MAIN_SOURCES = ("hmm_inferred", "hmm_true", "network", "fused")
_COLOURS = {
    "hmm_inferred": "tab:blue",
    "hmm_true": "tab:cyan",
    "network": "tab:green",
    "fused": "tab:red",
    "fused_untempered": "tab:orange",
}


def plot_confusions(results: LearningResults, path: Path) -> Path:
    plt = plotting.pyplot()
    actions = results.actions
    k = len(actions)
    fig, axes = plt.subplots(
        1, len(MAIN_SOURCES), figsize=(3.4 * len(MAIN_SOURCES), 3.9), layout="constrained"
    )
    for ax, source in zip(axes, MAIN_SOURCES, strict=True):
        score = results.main.scores[source]
        conf = score.confusion
        ax.imshow(conf, cmap="Blues", vmin=0, vmax=max(int(conf.sum(axis=1).max()), 1))
        for i in range(k):
            for j in range(k):
                v = int(conf[i, j])
                colour = "white" if v > conf.sum(axis=1).max() / 2 else "black"
                ax.text(j, i, str(v), ha="center", va="center", color=colour)
        ax.set_xticks(range(k), actions)
        ax.set_yticks(range(k), actions)
        ax.set_xlabel("predicted")
        ax.set_title(
            f"{SOURCE_NAMES[source].split(',')[0]}\naccuracy {score.accuracy:.1%}", fontsize=9
        )
    axes[0].set_ylabel("true action")
    fig.suptitle(
        f"held-out demonstrations (n={results.n_test}), "
        f"{results.main.n_per_action} watched per action, with words",
        fontsize=10,
    )
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_curves(results: LearningResults, path: Path) -> Path:
    plt = plotting.pyplot()
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 5.4), layout="constrained")
    for words, style in ((True, "-"), (False, "--")):
        conds = sorted(
            (c for c in results.ablation if c.words == words), key=lambda c: c.n_per_action
        )
        ns = [c.n_per_action for c in conds]
        tag = "with words" if words else "without words"
        for source in (*MAIN_SOURCES, "fused_untempered"):
            if source == "hmm_true" and not words:
                continue  # does not depend on words: drawn once
            if source == "fused_untempered" and not words:
                continue
            left.plot(
                ns,
                [100 * c.accuracy(source) for c in conds],
                style,
                marker="o",
                color=_COLOURS[source],
                alpha=0.5 if source == "fused_untempered" else 1.0,
                label=f"{SOURCE_NAMES[source].split(',')[0]}"
                + ("" if source in ("hmm_true", "fused_untempered") else f", {tag}"),
            )
        for measure, marker, colour, what in (
            ("accuracy", "o", "k", "all watched"),
            ("kept_accuracy", "s", "tab:purple", f"kept (P ≥ {results.config.threshold:g})"),
        ):
            right.plot(
                ns,
                [100 * c.labelling[measure] for c in conds],
                style,
                marker=marker,
                color=colour,
                label=f"{what}, {tag}",
            )
    for ax in (left, right):
        ax.set_xscale("log")
        ns_all = sorted({c.n_per_action for c in results.ablation})
        ax.set_xticks(ns_all, [str(n) for n in ns_all])
        ax.minorticks_off()
        ax.set_xlabel("demonstrations watched per action")
        ax.grid(alpha=0.3)
    left.set_ylabel("accuracy on held-out demonstrations (%)")
    left.set_title("action recognition")
    left.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2)
    right.set_ylabel("label accuracy (%)")
    right.set_title("labels inferred by the network (step 2)")
    right.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2)
    lo = min(
        [100 * c.accuracy(s) for c in results.ablation for s in SOURCES]
        + [100 * c.labelling["accuracy"] for c in results.ablation]
    )
    for ax in (left, right):
        ax.set_ylim(max(0.0, math.floor(lo / 5) * 5 - 5), 101)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _pct(x: float) -> str:
    return "–" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{100 * x:.1f}%"


def _cell(text: str) -> str:
    """Text safe inside a Markdown table cell."""
    return text.replace("|", "\\|")


def _confusion_md(actions: Sequence[str], conf: np.ndarray) -> list[str]:
    lines = ["| true \\ predicted | " + " | ".join(actions) + " |"]
    lines.append("|---" * (len(actions) + 1) + "|")
    for a, row in zip(actions, conf, strict=True):
        lines.append(f"| {a} | " + " | ".join(str(int(v)) for v in row) + " |")
    return lines


def _kappa(c: Condition) -> str:
    return "1 (not calibrated)" if c.kappa is None else f"{c.kappa:.2f}"


def report_markdown(results: LearningResults) -> str:
    r = results
    cfg = r.config
    obs = cfg.observation
    main = r.main
    acc = {s: main.accuracy(s) for s in SOURCES}
    check = r.acceptance()
    lab = main.labelling
    t = cfg.training
    arcs = ", ".join(f"{p}→{c}" for p, c in r.network["arcs"])
    lines = [
        "# Developmental learning: from the robot's own experience to recognising a human",
        "",
        f"Robot data: `{r.robot_data}` ({r.network['rows']} rows). Human data: `{r.human_data}`. "
        f"Seed {cfg.seed}. Run time {r.seconds:.1f} s.",
        "",
        "## What was done",
        "1. **Self phase.** The Affordance–Words network learned from the robot's exploration "
        f"(K2/BIC structure, BDeu/ML parameters). Affordance arcs: {arcs}; "
        f"{r.network['word_arcs']} word arcs.",
        "2. **Observation phase.** The robot watched "
        f"{r.n_watched[main.n_per_action]} human demonstrations ({main.n_per_action} per "
        "action). Each is a skeleton gesture, an object (seen correctly), effects and, "
        f"with probability {obs.p_words:g}, a sentence from the same narrator as the robot's "
        f"training data. The person's actions vary more than the robot's (log-normal "
        f"σ={obs.action_noise:g} against 0.15) and the robot measures them with a further "
        f"σ={obs.perception_noise:g} error; each effect is missed with probability "
        f"{obs.p_effect_missed:g}. Drawn: {_pct(r.observed_noise['effects_perceived_fraction'])} "
        "of effects perceived, "
        f"{_pct(r.observed_noise['perceived_effects_wrong_fraction'])} of those with the wrong "
        f"label, words heard for {_pct(r.observed_noise['words_heard_fraction'])} of "
        "demonstrations. Gestures vary in speed, amplitude and timing, with tracker noise, drift "
        "and glitches. The network gives P_BN(A | object, effects, words) for each "
        "demonstration; heard words enter as soft evidence through a hearing channel of "
        f"error {cfg.word_error:g}.",
        f"   **Labelling rule:** keep a demonstration when max P_BN ≥ {cfg.threshold:g} and label "
        "it with that action; drop the others (at least "
        f"{cfg.min_per_action} kept per inferred action). Keeping rather than weighting: "
        "hmmlearn's EM takes no per-sequence weights, and a wrong label costs more than a dropped "
        "demonstration (it corrupts one model and starves another).",
        f"3. **Gesture models.** One left-to-right GMM-HMM per action ({t.n_states} states, "
        f"{t.n_mix} Gaussian(s), full covariance, ≤{t.n_iter} EM iterations), trained on the kept "
        "demonstrations and their inferred labels.",
        f"4. **Evaluation** on {r.n_test} held-out demonstrations with true labels. The fused "
        "model enters the HMMs' evidence as soft evidence on Action (P_comb). Raw HMM posteriors "
        "are 0 or 1 (the HMM counts ~100 correlated frames as independent evidence), so the "
        "evidence is tempered, P_HMM ∝ exp(κ·(1/T)·log L), with κ calibrated by the robot on its "
        "own watched demonstrations and inferred labels (2-fold cross-fitting, maximum "
        f"likelihood): κ = {_kappa(main)}. No true label is used before evaluation.",
        "",
        "## Results (main run: "
        f"{main.n_per_action} demonstrations per action, words heard when spoken)",
        "",
        "| source | accuracy |",
        "|---|---|",
        *(f"| {_cell(SOURCE_NAMES[s])} | {_pct(acc[s])} |" for s in SOURCES),
        "",
        f"Step 2 label accuracy: {_pct(lab['accuracy'])} of {lab['n']} watched demonstrations "
        f"({_pct(main.label_accuracy_by_words['heard'])} with words heard, "
        f"{_pct(main.label_accuracy_by_words['not_heard'])} without); {lab['kept']} kept, of "
        f"which {_pct(lab['kept_accuracy'])} correctly labelled; the rule dropped "
        f"{lab['dropped_wrong']} wrong and {lab['dropped_right']} right labels.",
        "",
        "Acceptance:",
        f"- HMMs on inferred labels reach {_pct(check['hmm_inferred_over_true'])} of the accuracy "
        "of HMMs on true labels (needed: ≥ 90%): "
        f"{'**yes**' if check['inferred_reaches_90_percent'] else '**NO**'}.",
        "- The fused model is at least as accurate as the HMMs alone and the network alone: "
        f"{'**yes**' if check['fused_at_least_both'] else '**NO**'}.",
        "",
        f"![confusion matrices]({CONFUSIONS_PNG})",
        "",
    ]
    for s in MAIN_SOURCES:
        lines += [
            f"**{SOURCE_NAMES[s]}**",
            "",
            *_confusion_md(r.actions, main.scores[s].confusion),
            "",
        ]
    lines += [
        "## Ablations: words, and the number of demonstrations",
        "",
        "Each row watches the first N demonstrations per action of the same stream (nested sets) "
        "and is evaluated on the same held-out demonstrations. (b) does not depend on words.",
        "",
        "| N/action | words | labels right | kept (right) | κ | (a) HMM inferred | (b) HMM true "
        "| (c) network | (d) fused | (d') untempered |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for c in r.ablation:
        lb = c.labelling
        lines.append(
            f"| {c.n_per_action} | {'yes' if c.words else 'no'} | {_pct(lb['accuracy'])} | "
            f"{lb['kept']}/{lb['n']} ({_pct(lb['kept_accuracy'])}) | {_kappa(c)} | "
            + " | ".join(_pct(c.accuracy(s)) for s in SOURCES)
            + " |"
        )
    lines += ["", f"![accuracy against the number of demonstrations]({CURVE_PNG})", ""]
    lines += _findings(r)
    return "\n".join(lines) + "\n"


def _findings(r: LearningResults) -> list[str]:
    main = r.main
    acc = {s: main.accuracy(s) for s in SOURCES}
    with_w = {c.n_per_action: c for c in r.ablation if c.words}
    without = {c.n_per_action: c for c in r.ablation if not c.words}
    fused_wins = sum(
        c.accuracy("fused") >= max(c.accuracy("hmm_inferred"), c.accuracy("network"))
        for c in r.ablation
    )
    temper = sum(c.accuracy("fused") >= c.accuracy("fused_untempered") for c in r.ablation)
    n = len(r.ablation)
    out = [
        "## What the numbers say",
        f"- On the main run the HMMs are wrong on {_pct(1 - acc['hmm_inferred'])} of held-out "
        f"demonstrations, the network on {_pct(1 - acc['network'])}, the fused model on "
        f"{_pct(1 - acc['fused'])}. The fused model is at least as good as both sources in "
        f"{fused_wins} of {n} ablation conditions.",
    ]
    if 2 * temper > n:
        out.append(
            f"- Tempering the gesture evidence helps: fusing the raw HMM posterior gives "
            f"{_pct(acc['fused_untempered'])} instead of {_pct(acc['fused'])} on the main run "
            "(a source that is certain even when wrong overrides the other); the tempered one "
            f"is at least as good in {temper} of {n} conditions."
        )
    else:
        out.append(
            f"- Tempering does not help here: the untempered fusion gives "
            f"{_pct(acc['fused_untempered'])} against {_pct(acc['fused'])} on the main run, "
            f"and is better in {n - temper} of {n} conditions. κ is calibrated against the "
            f"network's own labels, which are right only {_pct(main.labelling['accuracy'])} of "
            "the time here; fitting noisy labels makes κ small, so the network, itself "
            "overconfident when wrong, dominates the fused model."
        )
    pairs = [(c, without[c.n_per_action]) for c in with_w.values() if c.n_per_action in without]
    if pairs:
        c0, c1 = pairs[0]
        label_gain = ", ".join(
            f"{100 * (a.labelling['accuracy'] - b.labelling['accuracy']):+.1f} (N={a.n_per_action})"
            for a, b in pairs
        )
        out.append(
            f"- Words: the network alone is {_pct(c0.accuracy('network'))} accurate with them "
            f"and {_pct(c1.accuracy('network'))} without; label accuracy changes by "
            f"{label_gain} points. They are heard for "
            f"{_pct(r.observed_noise['words_heard_fraction'])} of the demonstrations, and the "
            "narrator's verbs are sometimes wrong."
        )
    ratios = [
        c.accuracy("hmm_inferred") / c.accuracy("hmm_true")
        for c in r.ablation
        if c.accuracy("hmm_true") > 0
    ]
    ns = sorted(with_w)
    if ratios and ns:
        first, last = with_w[ns[0]], with_w[ns[-1]]
        out.append(
            "- Inferred labels against true labels for training the HMMs: (a) reaches "
            f"{_pct(min(ratios))}–{_pct(max(ratios))} of (b) across the ablation. With true "
            f"labels the HMMs go from {_pct(first.accuracy('hmm_true'))} (N={ns[0]}) to "
            f"{_pct(last.accuracy('hmm_true'))} (N={ns[-1]}): when that curve is flat, the "
            "HMMs' errors come from the gestures themselves (sloppy executions, tracker "
            "glitches), not from too little or wrongly labelled data."
        )
    out.append(
        "- Assumption behind the fusion gain: the gesture's difficulty and the effects' noise are "
        "independent in these demonstrations. A sloppy gesture that also produces atypical "
        "effects (a tap so weak the object barely moves) would make the sources err together and "
        "shrink the gain."
    )
    return out


def write_outputs(results: LearningResults, out_dir: str | Path) -> dict[str, Path]:
    """learning.md, results.json and the PNG plots in `out_dir`; returns their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        "results": out / RESULTS_FILE,
        "confusions": plot_confusions(results, out / CONFUSIONS_PNG),
        "curves": plot_curves(results, out / CURVE_PNG),
        "report": out / REPORT_FILE,
    }
    paths["results"].write_text(
        json.dumps(_finite(results.to_dict()), indent=1) + "\n", encoding="utf-8"
    )
    paths["report"].write_text(report_markdown(results), encoding="utf-8")
    return paths


def _finite(obj: Any) -> Any:
    """NaN → null, so the JSON is standard."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_finite(v) for v in obj]
    return obj
