"""`beyond segment`: objects on a tabletop frame (image or MCAP recording), with their features
and labels; also the exploration phase that learns the clusters, and the evaluation on simulated
experiments (confusion matrices)."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console

from beyond_self.commands import argtypes
from beyond_self.commands.terminal import progress_bar
from beyond_self.core.errors import InputError

HELP = "segment tabletop objects in an image or MCAP recording; learn or evaluate the clusters"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "source", nargs="?", metavar="IMAGE_OR_MCAP", help="a PPM/PGM/PNG image or an MCAP file"
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.add_argument(
        "--overlay",
        type=argtypes.output_file,
        metavar="OUT.png",
        help="draw contours, centroids, labels",
    )
    parser.add_argument("--clusters", metavar="FILE.json", help="clusters file (default: shipped)")
    parser.add_argument(
        "--background", metavar="EMPTY", nargs="+", help="image(s) of the empty table"
    )
    parser.add_argument("--size", metavar="WxH", help="require frames of this size, e.g. 320x240")
    parser.add_argument(
        "--frame", type=argtypes.count(0), help="MCAP: only the camera frame with this index"
    )
    parser.add_argument(
        "--reference-mask", metavar="MASK", help="report foreground IoU against this mask image"
    )
    parser.add_argument("--effects", action="store_true", help="MCAP: also measure the effects")
    for flag, output, metavar, what in (  # the two modes that simulate instead of reading SOURCE
        (
            "--learn",
            argtypes.output_file,
            "OUT.json",
            "run the exploration phase and write the clusters",
        ),
        (
            "--evaluate",
            argtypes.output_dir,
            "OUT_DIR",
            "score on simulated data; confusion matrices (PNG)",
        ),
    ):
        parser.add_argument(flag, type=output, metavar=metavar, help=what)
    parser.add_argument(
        "--experiments", type=argtypes.count(1, 100_000), default=216, help="simulated experiments"
    )
    parser.add_argument(
        "--stills", type=argtypes.count(0, 100_000), default=60, help="--evaluate: still scenes"
    )
    argtypes.add_seed(parser, "seed of the simulation")


def run(args: argparse.Namespace) -> int:
    modes = [args.source is not None, args.learn is not None, args.evaluate is not None]
    if sum(modes) != 1:
        raise InputError("give exactly one of: an IMAGE_OR_MCAP, --learn OUT.json, --evaluate DIR")
    if args.experiments < 1 or args.stills < 0:
        raise InputError("--experiments must be ≥ 1 and --stills ≥ 0")
    if args.learn is not None:
        return _learn(args)
    if args.evaluate is not None:
        return _evaluate(args)
    return _segment(args)


def _size(text: str | None) -> tuple[int, int] | None:
    if text is None:
        return None
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise InputError(f"--size {text!r} is not WIDTHxHEIGHT, e.g. 320x240") from None
    if w <= 0 or h <= 0:
        raise InputError(f"--size {text!r} must be positive")
    return w, h


def _clusters(path: str | None) -> Any:
    from beyond_self.cognition.vision.clusters import ClusterModel

    return ClusterModel.load(path)


def _segment(args: argparse.Namespace) -> int:
    from beyond_self.cognition.vision.background import BackgroundModel
    from beyond_self.cognition.vision.images import read_image

    source = Path(args.source)
    size = _size(args.size)
    clusters = _clusters(args.clusters)
    background = None
    if args.background:
        background = BackgroundModel.fit([read_image(p, size) for p in args.background])
    if source.suffix.lower() == ".mcap":
        return _segment_mcap(args, source, clusters, background, size)
    frame = read_image(source, size)
    if background is not None and background.shape != frame.shape[:2]:
        raise InputError(f"{source} and the background images differ in size")
    report, result = _describe(frame, clusters, background, str(source))
    if args.reference_mask:
        mask = read_image(args.reference_mask, (frame.shape[1], frame.shape[0])).any(axis=2)
        fg = result.segmentation.foreground
        union = int((fg | mask).sum())
        report["iou"] = round(float((fg & mask).sum() / union), 4) if union else 0.0
    if args.overlay:
        from beyond_self.cognition.vision.overlay import save_overlay

        save_overlay(args.overlay, frame, result.segmentation, result.objects, title=source.name)
    if args.json:
        print(json.dumps(report))
    else:
        _print_table(report)
        if args.overlay:
            print(f"overlay: {args.overlay}")
    return 0


def _describe(
    frame: np.ndarray, clusters: Any, background: Any, name: str
) -> tuple[dict[str, Any], Any]:
    from beyond_self.cognition.vision.pipeline import describe_frame

    result = describe_frame(frame, clusters, background)
    report: dict[str, Any] = {
        "source": name,
        "width": int(frame.shape[1]),
        "height": int(frame.shape[0]),
        "objects": [o.to_json() for o in result.objects],
    }
    if result.segmentation.hand is not None:
        cx, cy = result.segmentation.hand.centroid()
        report["hand"] = {"centroid": [round(cx, 2), round(cy, 2)]}
    return report, result


def _print_table(report: dict[str, Any]) -> None:
    print(f"{report['source']}: {len(report['objects'])} object(s)")
    head = f"{'id':>3} {'x':>7} {'y':>7} {'area':>6} {'color':>8} {'shape':>7} {'size':>7}"
    print(head + f" {'circ':>6} {'rect':>6} {'diam_m':>7}  L*a*b*")
    for o in report["objects"]:
        f = o["features"]
        lab = " ".join(f"{v:.0f}" for v in f["lab"])
        print(
            f"{o['id']:>3} {o['centroid'][0]:>7.1f} {o['centroid'][1]:>7.1f} {o['area']:>6} "
            f"{o.get('color', '-'):>8} {o.get('shape', '-'):>7} {o.get('size', '-'):>7} "
            f"{f['circularity']:>6.3f} {f['rectangularity']:>6.3f} {f['diameter_m']:>7.3f}  {lab}"
        )
    if "hand" in report:
        print(f"hand at {report['hand']['centroid']}")
    if "iou" in report:
        print(f"foreground IoU against the reference mask: {report['iou']:.3f}")


# ---------------------------------------------------------------- MCAP


def camera_frames(path: Path) -> Iterator[tuple[int, np.ndarray]]:
    """(stamp ns, RGB frame) of every tabletop camera message (raw or compressed) in a
    recording (not a person's camera, schemas.keys.TABLETOP_CAMERA)."""
    from beyond_self.runtime.recording.images import image_from_message
    from beyond_self.runtime.recording.reader import read_recording
    from beyond_self.schemas.keys import TABLETOP_CAMERA, split_key
    from beyond_self.schemas.messages import CameraFrame, CompressedCameraFrame

    for item in read_recording(path):
        split = split_key(item.key)
        if item.cls not in (CameraFrame, CompressedCameraFrame) or split is None:
            continue
        if split[1] not in TABLETOP_CAMERA:
            continue
        msg = item.message()
        assert isinstance(msg, CameraFrame | CompressedCameraFrame)
        yield item.publish_time, image_from_message(msg)


def _segment_mcap(
    args: argparse.Namespace, source: Path, clusters: Any, background: Any, size: Any
) -> int:
    frames = []
    for index, (stamp, frame) in enumerate(camera_frames(source)):
        if args.frame is not None and index != args.frame:
            continue
        if size is not None and (frame.shape[1], frame.shape[0]) != size:
            raise InputError(
                f"camera frame {index} is {frame.shape[1]}x{frame.shape[0]}; "
                f"expected {size[0]}x{size[1]}"
            )
        frames.append((index, stamp, frame))
    if not frames:
        what = f"camera frame {args.frame}" if args.frame is not None else "camera frames"
        raise InputError(f"{source} holds no {what} (foxglove.RawImage / CompressedImage)")
    from beyond_self.cognition.vision.background import BackgroundModel

    bg = background or BackgroundModel.from_frame(frames[0][2])
    out: dict[str, Any] = {"source": str(source), "frames": []}
    for index, stamp, frame in frames:
        report, result = _describe(frame, clusters, bg, f"{source.name}#{index}")
        report.pop("source")
        out["frames"].append({"index": index, "stamp_ns": stamp, **report})
        if args.overlay and index == frames[0][0]:
            from beyond_self.cognition.vision.overlay import save_overlay

            save_overlay(
                args.overlay,
                frame,
                result.segmentation,
                result.objects,
                title=f"{source.name} frame {index}",
            )
    if args.effects and len(frames) >= 3:
        from beyond_self.cognition.vision.pipeline import analyse_frames

        stamps = np.array([s for _, s, _ in frames], dtype=np.float64)
        fps = float((len(stamps) - 1) / max((stamps[-1] - stamps[0]) / 1e9, 1e-9))
        analysis = analyse_frames([f for _, _, f in frames], fps, clusters, background=bg)
        out["effects"] = {
            "fps": round(fps, 3),
            "measures": {k: round(v, 4) for k, v in analysis.effects.as_dict().items()},
            "labels": analysis.labels,
        }
    if args.json:
        print(json.dumps(out))
    else:
        for fr in out["frames"]:
            _print_table({"source": f"{source.name} frame {fr['index']}", **fr})
        if "effects" in out:
            print(f"effects: {out['effects']['measures']} -> {out['effects']['labels']}")
    return 0


# ---------------------------------------------------------------- learn / evaluate


def _learn(args: argparse.Namespace) -> int:

    from beyond_self.cognition.vision.pipeline import learn_clusters
    from beyond_self.cognition.vision.tabletop import exploration

    command = (
        f"beyond segment --learn {args.learn} --experiments {args.experiments} --seed {args.seed}"
    )
    with progress_bar(Console(stderr=True)) as progress:
        task = progress.add_task("exploration", total=args.experiments)
        model, _rows, _truth = learn_clusters(
            exploration(args.experiments, args.seed),
            seed=args.seed,
            progress=lambda i: progress.update(task, completed=i),
            created_by=command,
        )
    path = model.save(args.learn)
    print(f"learned clusters from {args.experiments} simulated experiments -> {path}")
    for var, disc in model.variables.items():
        acc = model.training["agreement_with_truth"][var]
        print(f"  {var:<10} {', '.join(disc.names):<30} agreement with truth {acc:.3f}")
    return 0


def _evaluate(args: argparse.Namespace) -> int:

    from beyond_self.cognition.vision.evaluation import evaluate_experiments, evaluate_stills
    from beyond_self.cognition.vision.tabletop import exploration

    clusters = _clusters(args.clusters)
    out = Path(args.evaluate)
    seed = args.seed + 1_000_003  # never the exploration's own experiments
    objects = evaluate_stills(args.stills, seed, clusters) if args.stills else None
    with progress_bar(Console(stderr=True)) as progress:
        task = progress.add_task("experiments", total=args.experiments)
        exps = evaluate_experiments(
            exploration(args.experiments, seed),
            clusters,
            progress=lambda i: progress.update(task, completed=i),
        )
    summary: dict[str, Any] = {"experiments": exps.summary()}
    print(f"simulated experiments (seed {seed}), one object each:")
    print(exps.format())
    exps.plot(out / "confusion_experiments.png", f"{args.experiments} simulated experiments")
    if objects is not None:
        print(f"\nstill scenes (seed {seed}), objects:")
        print(objects.format())
        objects.plot(out / "confusion_objects.png", f"{args.stills} still scenes")
        summary["objects"] = objects.summary()
        if objects.failures:
            print("\n".join(objects.failures), file=sys.stderr)
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    print(f"\nconfusion matrices: {out}/confusion_*.png, figures: {out}/summary.json")
    return 0
