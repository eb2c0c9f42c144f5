"""`beyond gesture train|stream|evaluate|realism`: the per-action gesture HMMs.

MODELS is a file written by `train`, one of the article's MATLAB files, or `default`. DATA is
`synthetic`, a folder of hand recordings named after their action (the article's human_data/),
or MCAP recordings whose labels come from their "beyond" metadata (`gesture_actions`, optionally
`gesture_frames`) or else their file name (docs/science/gestures.md). `train` takes --data
several times and trains on all of it; `evaluate cv` cross-validates, `evaluate compare` puts
our models, cross-validation and the article's side by side; `realism` compares the simulator's
gestures with DATA's.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.table import Table

from beyond_self.cognition.gestures.datasets import (
    SYNTHETIC,
    action_from_name,
    load_gestures,
    skeleton_gestures,
)
from beyond_self.cognition.gestures.evaluation import FOLDS, LabelledGesture
from beyond_self.cognition.gestures.features import (
    LOG_SCALE,
    MOTION,
    extract_features,
    gesture_features,
)
from beyond_self.cognition.gestures.hmm import GestureModels
from beyond_self.cognition.gestures.logs import check_positions, parse_frames, read_hand_log
from beyond_self.cognition.gestures.model_files import load_models, save_models
from beyond_self.cognition.gestures.training import train_models
from beyond_self.cognition.paths import data_set
from beyond_self.commands import argtypes
from beyond_self.commands.gesture_reports import evaluate_command, realism_command
from beyond_self.commands.hmm_options import add_training_options, training_config
from beyond_self.commands.terminal import progress_bar
from beyond_self.core.errors import InputError
from beyond_self.runtime import outputs

HELP = "train, run (frame by frame) and evaluate the gesture HMMs"

TRAIN_SEED = 0
TRAIN_COUNT = 60  # synthetic gestures per action of the default models
EVAL_SEED = 1  # evaluate's synthetic default: held-out gestures, never seen by `train`
DEFAULT = "default"
PLOTS = "gesture-evaluation"  # evaluate's and realism's folder under the outputs folder


def _data_args(p: argparse.ArgumentParser, seed: int, count: int = 30) -> None:
    p.add_argument(
        "--count",
        type=argtypes.count(1, 100_000),
        default=count,
        help=f"synthetic gestures per action (default {count})",
    )
    argtypes.add_seed(p, f"synthetic data seed (default {seed})", default=seed)
    p.add_argument(
        "--push-as",
        choices=("grasp", "tap", "touch"),
        default=None,
        help="count push recordings as this action (default: leave them out)",
    )


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="gesture_command", metavar="SUBCOMMAND", required=True)

    train = sub.add_parser("train", help="train one left-to-right GMM-HMM per action")
    train.add_argument(
        "--data",
        action="append",
        default=None,
        help="'synthetic' (default), a folder of hand recordings (grasp1_hand/ ...), or MCAP "
        "recordings (a .mcap file or a folder of them); a name such as human_data is also looked "
        "up in the article's data folder ($BEYOND_DATA); give it several times to train on all",
    )
    argtypes.add_output(train, "model file to write (.json)", required=True, old="--out")
    add_training_options(train, mix=3, iterations=30, states="HMM states per action")
    _data_args(train, TRAIN_SEED, TRAIN_COUNT)

    stream = sub.add_parser("stream", help="run the streaming recogniser over a hand log")
    stream.add_argument("models", help="model file (.json), the article's .mat, or 'default'")
    stream.add_argument("log", type=Path, help="recording folder or its data.log")
    stream.add_argument("--frames", default=None, help="A:B, 1-based inclusive (default: all)")
    stream.add_argument(
        "--scale",
        type=argtypes.number(float, lo=0, hi=1e6, lo_open=True),
        default=LOG_SCALE,
        help=f"multiply logged positions by S (default {LOG_SCALE}: logs -> model units)",
    )
    stream.add_argument("--json", action="store_true", help="print JSON instead of a table")
    stream.add_argument("--priors", default=None, help="action priors, comma separated")
    stream.add_argument(
        "--garbage", action="store_true", help="add the garbage model as a class, if loaded"
    )
    stream.add_argument(
        "--plot", type=argtypes.output_file, default=None, help="also write a PNG plot here"
    )

    ev = sub.add_parser("evaluate", help="accuracy, confusion and early recognition")
    ev.add_argument(
        "models",
        help="model file, 'default', 'cv' (cross-validation) or 'compare' (default models, "
        "cross-validation and the article's models side by side)",
    )
    ev.add_argument(
        "data",
        help="'synthetic', a folder of hand recordings, or MCAP recordings; a name such as "
        "human_data is also looked up in the article's data folder ($BEYOND_DATA)",
    )
    ev.add_argument("--json", action="store_true", help="print the report as JSON")
    ev.add_argument(
        "--folds",
        choices=FOLDS,
        default="recording",
        help="cv: leave one recording out (default) or one gesture out",
    )
    ev.add_argument(
        "--with",
        dest="also",
        action="append",
        default=[],
        help="cv: also train every fold on this data ('synthetic', recordings); never tested",
    )
    ev.add_argument(
        "--article",
        type=Path,
        default=None,
        help="compare: the article's models (default: HMM_M3_Q6_mixsplit.mat in DATA)",
    )
    argtypes.add_output(
        ev,
        f"folder for the PNG plots (default: {PLOTS} under {outputs.DESCRIPTION})",
        folder=True,
        old="--out",
    )
    add_training_options(ev, mix=3, iterations=30, states="HMM states per action")
    _data_args(ev, EVAL_SEED)

    realism = sub.add_parser("realism", help="the simulator's gestures next to recorded ones")
    realism.add_argument(
        "data",
        help="a folder of hand recordings, or MCAP recordings; a name such as human_data is also "
        "looked up in the article's data folder ($BEYOND_DATA)",
    )
    argtypes.add_output(
        realism,
        f"folder for the PNG plot (default: {PLOTS} under {outputs.DESCRIPTION})",
        folder=True,
    )
    _data_args(realism, TRAIN_SEED)


def run(args: argparse.Namespace) -> int:
    command = args.gesture_command
    if command in ("evaluate", "realism") and args.output is None:
        args.output = outputs.out_dir() / PLOTS  # never the current folder unless asked
    if command == "evaluate":
        return evaluate_command(args, gestures, models_from)
    if command == "realism":
        return realism_command(args, gestures)
    return _train(args) if command == "train" else _stream(args)


def models_from(spec: str, *, include_garbage: bool = False) -> GestureModels:
    """A model set by name: 'default' (the shipped models) or a file."""
    if spec == DEFAULT:
        from beyond_self.cognition.gestures.default_models import default_models

        return default_models()
    return load_models(Path(spec), include_garbage=include_garbage)


def _mcap_gestures(path: Path, push_as: str | None) -> list[LabelledGesture]:
    """Labelled gestures of one MCAP recording (labels: see the module docstring)."""
    from beyond_self.runtime.recording.reader import inspect_recording, read_recording
    from beyond_self.schemas.keys import STREAMS
    from beyond_self.schemas.messages import SkeletonFrame

    suffix = "/" + STREAMS["skeleton"][0]
    meta = inspect_recording(path).metadata.get("beyond", {})
    frames = [
        msg
        for item in read_recording(path)
        if item.key.endswith(suffix) and isinstance(msg := item.message(), SkeletonFrame)
    ]
    if not frames:
        raise InputError(f"{path} holds no skeleton frames (keys ending in {suffix})")
    names = set.intersection(*(set(f.joints) for f in frames))
    if "right_hand" not in names:
        raise InputError(f"{path}: the joint 'right_hand' is not in every skeleton frame")
    joints: dict[str, np.ndarray] = {
        n: np.array([f.joints[n].position for f in frames], dtype=np.float64)
        for n in ("right_hand", "torso")
        if n in names
    }
    if meta.get("gesture_actions"):
        actions = [a.strip() for a in meta["gesture_actions"].split(",")]
    else:
        label = action_from_name(path.name, push_as)
        if label is None:
            raise InputError(
                f"{path}: no gesture labels; add metadata gesture_actions or name the file "
                "<action>....mcap"
            )
        actions = [label]
    bounds = None
    if meta.get("gesture_frames"):
        try:
            bounds = [
                (int(a), int(b))
                for a, b in (p.split(":") for p in meta["gesture_frames"].split(","))
            ]
        except ValueError:
            raise InputError(
                f"{path}: metadata gesture_frames {meta['gesture_frames']!r}; valid: 'a:b,c:d'"
            ) from None
    return skeleton_gestures(joints, actions, bounds=bounds, source=path.name)


def gestures(args: argparse.Namespace, spec: str) -> list[LabelledGesture]:
    """DATA as labelled gestures: synthetic, recording folders, or MCAP recordings (a name
    such as human_data is looked up in the article's data folder, cognition.paths.data_set)."""
    spec = data_set(spec, keep=(SYNTHETIC,))
    path = Path(spec)
    mcaps = [path] if path.suffix.lower() == ".mcap" else []
    if not mcaps and spec != SYNTHETIC and path.is_dir() and not (path / "data.log").exists():
        mcaps = sorted(path.glob("*.mcap"))
    if not mcaps:
        return load_gestures(spec, n_per_action=args.count, seed=args.seed, push_as=args.push_as)
    out: list[LabelledGesture] = []
    for p in mcaps:
        if not p.is_file():
            raise InputError(f"{p} does not exist; valid: an MCAP recording")
        out.extend(_mcap_gestures(p, args.push_as))
    return out


def _train(args: argparse.Namespace) -> int:
    console = Console(stderr=True)
    if args.output.suffix.lower() != ".json":
        raise InputError(f"--output {args.output} must end in .json")
    cfg = training_config(args)
    sources = [data_set(spec, keep=(SYNTHETIC,)) for spec in args.data or [SYNTHETIC]]
    data: dict[str, list[Any]] = {}
    for spec in sources:
        with console.status(f"loading gestures from {spec}"):
            for g in gestures(args, spec):
                data.setdefault(g.action, []).append(g.features)
    with progress_bar(console) as progress:
        task = progress.add_task("training HMMs", total=len(data))
        models = train_models(
            data,
            cfg,
            meta={
                "data": sources if len(sources) > 1 else sources[0],
                "seed": args.seed if SYNTHETIC in sources else None,
            },
            on_model=lambda a: progress.advance(task),
            features=MOTION,
        )
    save_models(models, args.output)
    counts = ", ".join(f"{a} {len(data[a])}" for a in models.actions)
    console.print(
        f"wrote {args.output}: {len(models.actions)} models ({counts} gestures), "
        f"floor {models.floor} per frame"
    )
    return 0


def _parse_priors(text: str | None, n: int) -> list[float] | None:
    if text is None:
        return None
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"--priors {text!r}; valid: {n} comma-separated numbers") from None
    if len(values) != n:
        raise InputError(f"--priors has {len(values)} values; valid: {n}, one per action")
    return values


def _stream(args: argparse.Namespace) -> int:
    from beyond_self.cognition.gestures.streaming import StreamingRecognizer

    models = models_from(args.models, include_garbage=args.garbage)
    log = read_hand_log(args.log)
    span = parse_frames(args.frames, len(log))
    positions = check_positions(extract_features(log.xyz, scale=args.scale), str(args.log))
    feats = gesture_features(models.features, positions, span.start, span.stop)
    rec = StreamingRecognizer(models, priors=_parse_priors(args.priors, len(models.actions)))
    results = [rec.push(x) for x in feats]
    first = span.start + 1
    if args.json:
        out = {
            "actions": list(models.actions),
            "first_frame": first,
            "frames": [r.to_dict() for r in results],
        }
        json.dump(out, sys.stdout)
        sys.stdout.write("\n")
    else:
        console = Console(width=None if sys.stdout.isatty() else 200)  # a table is never cut
        table = Table(title=f"{args.log} frames {first}-{span.stop}, scale {args.scale:g}")
        table.add_column("frame", justify="right")
        table.add_column("t", justify="right")
        for a in models.actions:
            table.add_column(f"P({a})", justify="right")
        for a in models.actions:
            table.add_column(f"log L {a}", justify="right")
        for r in results:
            best = int(np.argmax(r.posterior))
            cells = [
                f"[bold]{p:.3f}[/bold]" if i == best else f"{p:.3f}"
                for i, p in enumerate(r.posterior)
            ]
            table.add_row(str(first + r.t - 1), str(r.t), *cells, *(f"{v:.2f}" for v in r.loglik))
        console.print(table)
        console.print(f"most probable action after {len(results)} frames: [bold]{results[-1].best}")
    if args.plot is not None:
        from beyond_self.cognition.gestures.evaluation import plot_stream
        from beyond_self.cognition.gestures.streaming import recognize_sequence

        plot_stream(recognize_sequence(rec.compiled, feats), args.plot, str(args.log), first)
    return 0
