"""The evidence options of `bn query`, `bn words`, `describe` and `ask`, parsed in one place.

`--evidence` (hard), `--soft` (a distribution over a variable's values), `--gesture` (P_HMM(A |
G) given directly) and `--gesture-log MODELS LOG` (P_HMM from running the recogniser over a hand
log; commands with the network at hand only, not `ask`). The grammar and the rules are
`cognition.bn.evidence`'s; this module wires them to argparse.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

from beyond_self.cognition.bn.evidence import (
    EVIDENCE_FORM,
    GESTURE_FORM,
    SOFT_FORM,
    Evidence,
    build_evidence,
    parse_evidence,
    parse_gesture,
    parse_soft,
)
from beyond_self.cognition.bn.model import BayesNet
from beyond_self.cognition.gestures.features import LOG_SCALE
from beyond_self.commands import argtypes
from beyond_self.core.errors import InputError


def add_evidence_arguments(parser: argparse.ArgumentParser, *, gesture_log: bool = True) -> None:
    parser.add_argument(
        "--evidence",
        nargs="+",
        action="extend",
        default=[],
        metavar=EVIDENCE_FORM,
        help="what is known for sure, e.g. Shape=circle Size=small",
    )
    parser.add_argument(
        "--soft",
        nargs="+",
        action="extend",
        default=[],
        metavar=SOFT_FORM,
        help="a distribution over VAR's values, by name (values not named get 0)",
    )
    parser.add_argument(
        "--gesture",
        nargs="+",  # one is valid; more reach parse_gesture, which names the new forms
        action="extend",
        default=[],
        metavar=GESTURE_FORM,
        help="P_HMM(A | G) to fuse with the network",
    )
    if not gesture_log:
        return
    parser.add_argument(
        "--gesture-log",
        nargs=2,
        type=Path,
        metavar=("MODELS", "LOG"),
        help="gesture evidence from the gesture HMMs MODELS (.json or the article's .mat) run "
        "over the hand log LOG",
    )
    parser.add_argument("--frames", default=None, metavar="A:B", help="frames of LOG (1-based)")
    parser.add_argument(
        "--scale",
        type=argtypes.number(float, lo=0, hi=1e6, lo_open=True),
        default=LOG_SCALE,
        metavar="S",
        help=f"multiply LOG positions by S (default {LOG_SCALE}: millimetres to metres)",
    )


def parse_evidence_args(args: argparse.Namespace) -> Evidence:
    """The evidence options as typed, by name: no network needed (`beyond ask` has none)."""
    return Evidence(
        parse_evidence(args.evidence), parse_soft(args.soft), parse_gesture(args.gesture)
    )


@dataclass(frozen=True)
class Resolved:
    """Evidence ready for the network, and a label saying what it was for people."""

    observed: dict[str, str]
    soft: dict[str, list[float]]
    description: list[str] = field(default_factory=list)

    def label(self) -> str:
        return ", ".join(self.description) if self.description else "nothing"


def resolve_evidence(args: argparse.Namespace, model: BayesNet) -> Resolved:
    """The evidence options (with --gesture-log run through the recogniser) against `model`."""
    evidence = parse_evidence_args(args)
    described = [*args.evidence, *(f"soft {s}" for s in args.soft)]
    if args.gesture_log is None:
        if args.frames is not None or args.scale != LOG_SCALE:
            raise InputError(
                "--frames and --scale apply to --gesture-log MODELS LOG; give --gesture-log"
            )
        if evidence.gesture:
            described.append("gesture " + _shown(evidence.gesture))
    else:
        if evidence.gesture:
            raise InputError(
                "give gesture evidence one way: --gesture ACTION=p,... or --gesture-log "
                "MODELS LOG, not both"
            )
        from beyond_self.cognition.gestures.log_evidence import recognize_log
        from beyond_self.cognition.gestures.model_files import load_models

        models_path, log_path = args.gesture_log
        result, first = recognize_log(load_models(models_path), log_path, args.frames, args.scale)
        gesture = {a: float(p) for a, p in zip(result.actions, result.final.posterior, strict=True)}
        evidence = replace(evidence, gesture=gesture)
        last = first + len(result) - 1
        described.append(f"gesture {log_path} frames {first}-{last} ({_shown(gesture)})")
    built = build_evidence(model, evidence)
    return Resolved(built.observed, built.soft, described)


def _shown(gesture: Mapping[str, float]) -> str:
    return ", ".join(f"{a} {p:.3f}" for a, p in gesture.items())
