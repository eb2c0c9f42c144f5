"""The evidence options shared by `bn query`, `bn words` and `describe`.

    --evidence VAR=VALUE ...      hard evidence
    --soft VAR=p1,p2,... ...      a distribution over VAR's values (definition order)
    --gesture MODELS LOG          action evidence from running the gesture recogniser on a log
    --frames A:B  --scale S       which frames of LOG (1-based, inclusive) and the position scale

With --gesture, P_HMM(A | G) after the last frame is fused with the network as SPEC.md says
(`cognition.fusion`), which is why the action may then be neither observed nor given as soft
evidence.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from pathlib import Path

from beyond.commands import argtypes
from cognition.bn.evidence import parse_evidence, parse_soft
from cognition.bn.model import BayesNet
from cognition.fusion import ACTION, action_vector
from cognition.gestures.features import LOG_SCALE
from core.errors import InputError


def add_evidence_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--evidence", nargs="+", action="extend", default=[], metavar="VAR=VALUE")
    parser.add_argument(
        "--soft",
        nargs="+",
        action="extend",
        default=[],
        metavar="VAR=p1,p2,...",
        help="a distribution over VAR's values, in definition order",
    )
    parser.add_argument(
        "--gesture",
        nargs=2,
        type=Path,
        metavar=("MODELS", "LOG"),
        help="action evidence from the gesture HMMs MODELS (.json or the article's .mat) run "
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
    parser.add_argument("--json", action="store_true")


@dataclass(frozen=True)
class Evidence:
    """Evidence ready for the network: hard values, soft vectors, and where the action came from."""

    observed: dict[str, str]
    soft: dict[str, list[float]]
    gesture: dict[str, float] | None = None  # P_HMM(A | G) by action, when --gesture was given
    description: list[str] = field(default_factory=list)

    def label(self) -> str:
        return ", ".join(self.description) if self.description else "nothing"


def resolve_evidence(args: argparse.Namespace, model: BayesNet) -> Evidence:
    observed = parse_evidence(args.evidence, model.definition)
    soft = parse_soft(args.soft, model.definition)
    described = [*args.evidence, *(f"soft {s}" for s in args.soft)]
    gesture = None
    if args.gesture is None:
        if args.frames is not None or args.scale != LOG_SCALE:
            raise InputError("--frames and --scale apply to --gesture MODELS LOG; give --gesture")
        return Evidence(observed, soft, None, described)
    if ACTION in observed or ACTION in soft:
        raise InputError(
            f"--gesture gives the action evidence; drop {ACTION} from --evidence/--soft"
        )
    from cognition.gestures.hmm import load_models
    from cognition.gestures.log_evidence import recognize_log

    models_path, log_path = args.gesture
    result, first = recognize_log(load_models(models_path), log_path, args.frames, args.scale)
    final = result.final
    gesture = {a: float(p) for a, p in zip(result.actions, final.posterior, strict=True)}
    soft[ACTION] = action_vector(model, gesture).tolist()
    shown = ", ".join(f"{a} {p:.3f}" for a, p in gesture.items())
    described.append(f"gesture {log_path} frames {first}-{first + len(result) - 1} ({shown})")
    return Evidence(observed, soft, gesture, described)
