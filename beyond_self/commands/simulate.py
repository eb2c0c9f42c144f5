"""`beyond simulate SCENE -o FILE.mcap`: a seeded synthetic recording of a person acting on objects.

Skeleton frames at 30 fps and tabletop camera frames (JPEG by default, so recordings stay small)
on one clock from a fixed epoch: the same arguments give the same bytes. The scene is
`cognition.scene`; this module turns it into bus messages in an MCAP file, with the scene's
truth in the file's metadata. `--check` reads the file back, runs what the services would on it,
prints one line per gesture against the truth and a verdict naming every variable it checked
(exit 1 if a gesture is missed or a required one differs: MEASURED says which are not).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TextIO

import numpy as np
from rich.console import Console

from beyond_self.cognition.scene import (
    CAMERA_FPS_RANGE,
    EPOCH_NS,
    PRESETS,
    SPEC_HELP,
    GestureCheck,
    GestureTruth,
    Scene,
    check_scene,
    parse_scene,
    simulate_scene,
)
from beyond_self.commands import argtypes
from beyond_self.commands.terminal import progress_bar
from beyond_self.core.errors import InputError
from beyond_self.runtime.recording.images import image_from_message, message_from_image
from beyond_self.runtime.recording.reader import inspect_recording, read_recording
from beyond_self.runtime.recording.writer import RecordingWriter
from beyond_self.schemas import CameraFrame, CompressedCameraFrame, Header, Joint, SkeletonFrame
from beyond_self.schemas.keys import DEFAULT_ROBOT, Keys

HELP = "write a seeded synthetic recording (skeleton + tabletop camera) of a scene to MCAP"

SOURCE = "simulator"
FRAME_ID = "camera"  # as runtime.recording.images names it
FORMATS = ("jpeg", "png", "raw")
POSITION_DECIMALS = 4  # 0.1 mm: finer than any body tracker, and the JSON stays short
METADATA_NAME = "beyond"
# every affordance variable of a scene is checked against its truth by `--check`; these must
# agree (the action recognised, the object seen at the start, the object's velocity)
CHECKED = ("Action", "Color", "Shape", "Size", "ObjVel")
# these are checked and counted but do not fail: the camera measures them over the gesture's
# frames (the approach too: a grasp's hand moving to a still box), the truth over the contact
MEASURED = ("HandVel", "ObjHandVel", "Contact")
REPORTED = (*CHECKED, *MEASURED)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "scene", metavar="SCENE", help=f"a preset ({', '.join(PRESETS)}) or {SPEC_HELP}"
    )
    parser.add_argument(
        "-o",
        "--output",
        type=argtypes.output_file,
        required=True,
        metavar="FILE.mcap",
        help="output file",
    )
    argtypes.add_seed(parser, "seed of the simulation (default 0)")
    parser.add_argument(
        "--camera-fps",
        type=argtypes.number(float),
        default=15.0,
        help=f"camera frame rate, {CAMERA_FPS_RANGE[0]:g}..{CAMERA_FPS_RANGE[1]:g} (default 15)",
    )
    parser.add_argument(
        "--format", choices=FORMATS, default="jpeg", help="camera frames (default jpeg)"
    )
    parser.add_argument(
        "--quality",
        type=argtypes.count(1, 95, "JPEG quality"),
        default=80,
        help="JPEG quality 1..95 (default 80)",
    )
    parser.add_argument(
        "--robot", default=DEFAULT_ROBOT, help=f"robot name in the keys (default {DEFAULT_ROBOT})"
    )
    parser.add_argument(
        "--check",
        action="store_true",
        help="read the file back and check that the pipeline recovers the scene's truth",
    )


def run(args: argparse.Namespace) -> int:
    items = parse_scene(args.scene)
    if not 1 <= args.quality <= 95:
        raise InputError(f"--quality {args.quality} out of range; valid: 1..95")
    keys = Keys(args.robot)
    out = Path(args.output)
    if not out.parent.is_dir():
        raise InputError(f"output folder {out.parent} does not exist")
    scene = simulate_scene(items, seed=args.seed, camera_fps=args.camera_fps)
    console = Console(stderr=True)
    progress = progress_bar(console)
    metadata = {
        "generator": "beyond simulate",
        "scene": args.scene,
        "items": ",".join(it.spec for it in scene.items),
        "seed": str(args.seed),
        "camera_fps": f"{args.camera_fps:g}",
        "format": args.format,
        "quality": str(args.quality) if args.format == "jpeg" else "",
        "robot": args.robot,
        "epoch_ns": str(EPOCH_NS),
        "truth": json.dumps(scene.truth(), sort_keys=True, separators=(",", ":")),
    }
    total = scene.n_skeleton_frames + scene.n_camera_frames
    with progress, RecordingWriter(out, metadata=metadata) as writer:
        task = progress.add_task(f"simulating {out.name}", total=total)
        for key, message in messages(scene, keys, args.format, args.quality):
            writer.write(key, message)
            progress.advance(task)
    size = out.stat().st_size
    print(
        f"{out}: {len(scene.items)} gesture(s), {scene.n_skeleton_frames} skeleton frames, "
        f"{scene.n_camera_frames} camera frames ({args.format}, {args.camera_fps:g} fps), "
        f"{scene.n_skeleton_frames / scene.skeleton.fps:.1f} s, {size / 1e6:.2f} MB"
    )
    for g in scene.gestures:
        labels = " ".join(f"{k}={v}" for k, v in g.labels.items())
        print(
            f"  {g.item.spec:<28} skeleton {g.bounds.start}-{g.bounds.stop} "
            f"camera {g.experiment[0]}-{g.experiment[1]}  {labels}"
        )
    if args.check:
        checks = check_recording(out)
        print_checks(checks, len(scene.items))
        print(verdict(checks, len(scene.items)))
        return 0 if checks_pass(checks, len(scene.items)) else 1
    return 0


def skeleton_message(scene: Scene, i: int, stamp: int) -> SkeletonFrame:
    joints = {
        name: Joint(
            position=(
                round(float(xyz[i, 0]), POSITION_DECIMALS),
                round(float(xyz[i, 1]), POSITION_DECIMALS),
                round(float(xyz[i, 2]), POSITION_DECIMALS),
            ),
            confidence=1.0,
        )
        for name, xyz in scene.skeleton.joints.items()
    }
    header = Header(
        version=SkeletonFrame.VERSION,
        source=SOURCE,
        seq=i,
        stamp=stamp,
        correlation=f"{SOURCE}/skeleton/{i}",
    )
    return SkeletonFrame(header=header, frame=i + 1, joints=joints)


def messages(
    scene: Scene, keys: Keys, fmt: str = "jpeg", quality: int = 80
) -> Iterator[tuple[str, SkeletonFrame | CameraFrame | CompressedCameraFrame]]:
    """The scene's messages in stamp order (a skeleton frame before a camera frame of the same
    stamp), each with its key."""
    if fmt not in FORMATS:
        raise InputError(f"camera format {fmt!r} unknown; valid: {', '.join(FORMATS)}")
    sk_stamps = scene.skeleton_stamps()
    cam_stamps = scene.camera_stamps()
    cam_key = keys.camera if fmt == "raw" else keys.camera_compressed
    cls = CameraFrame if fmt == "raw" else CompressedCameraFrame
    frames = scene.frames()
    n = 0
    for i, stamp in enumerate(sk_stamps):
        while n < len(cam_stamps) and cam_stamps[n] < stamp:
            yield cam_key, _camera(next(frames), cls, n, int(cam_stamps[n]), fmt, quality)
            n += 1
        yield keys.skeleton, skeleton_message(scene, i, int(stamp))
    for k in range(n, len(cam_stamps)):
        yield cam_key, _camera(next(frames), cls, k, int(cam_stamps[k]), fmt, quality)


def _camera(
    image: np.ndarray,
    cls: type[CameraFrame] | type[CompressedCameraFrame],
    n: int,
    stamp: int,
    fmt: str,
    quality: int,
) -> CameraFrame | CompressedCameraFrame:
    header = Header(
        version=cls.VERSION, source=SOURCE, seq=n, stamp=stamp, correlation=f"{SOURCE}/camera/{n}"
    )
    return message_from_image(header, image, fmt=fmt, quality=quality, frame_id=FRAME_ID)


# ---------------------------------------------------------------- --check


def check_recording(path: str | Path) -> list[GestureCheck]:
    """Read a simulated recording back and run `cognition.scene.check_scene` on it."""
    info = inspect_recording(path)
    if info.error:
        raise InputError(info.damage())
    meta = info.metadata.get(METADATA_NAME, {})
    if "truth" not in meta:
        raise InputError(f"{path} has no scene truth in its metadata; valid: a simulated recording")
    truth = [GestureTruth.from_json(d) for d in json.loads(meta["truth"])]
    joints: dict[str, list[tuple[float, float, float]]] = {}
    sk_stamps: list[int] = []
    cam_stamps: list[int] = []
    images: list[np.ndarray] = []
    for item in read_recording(path):
        if item.cls is SkeletonFrame:
            msg = item.message()
            assert isinstance(msg, SkeletonFrame)
            sk_stamps.append(msg.header.stamp)
            for name, joint in msg.joints.items():
                joints.setdefault(name, []).append(joint.position)
        elif item.cls in (CameraFrame, CompressedCameraFrame):
            cam = item.message()
            assert isinstance(cam, CameraFrame | CompressedCameraFrame)
            cam_stamps.append(cam.header.stamp)
            images.append(image_from_message(cam))
    skeleton = {name: np.asarray(v, dtype=np.float64) for name, v in joints.items()}
    return check_scene(skeleton, np.asarray(sk_stamps), np.asarray(cam_stamps), images, truth)


def checks_pass(checks: list[GestureCheck], n_items: int) -> bool:
    """One gesture found per item, and each one's required variables (CHECKED) as the truth."""
    if sorted(c.index for c in checks) != list(range(n_items)):
        return False
    return all(c.agrees(v) for c in checks for v in CHECKED)


def verdict(checks: list[GestureCheck], n_items: int) -> str:
    """One line: pass or FAIL, the gestures found for the items, and each variable checked,
    with how many of the found gestures got it right when not all did."""
    found = sorted({c.index for c in checks if c.index >= 0})
    matched = [c for c in checks if c.index >= 0]

    def fields(variables: tuple[str, ...]) -> str:
        said = []
        for v in variables:
            right = sum(c.agrees(v) for c in matched)
            said.append(f"{v} ok" if right == len(matched) else f"{v} {right} of {len(matched)}")
        return ", ".join(said)

    word = "pass" if checks_pass(checks, n_items) else "FAIL"
    return (
        f"check {word}: {len(found)} of {n_items} item(s) found ({len(checks)} gesture(s)); "
        f"required {fields(CHECKED)}; measured, not required {fields(MEASURED)}"
    )


def print_checks(checks: list[GestureCheck], n_items: int, file: TextIO | None = None) -> None:
    stream = file or sys.stdout
    print(f"check: {len(checks)} gesture(s) found for {n_items} item(s)", file=stream)
    for c in checks:
        parts = []
        for v in REPORTED:
            got = c.action if v == "Action" else c.labels.get(v, "?")
            want = c.truth.get(v, "?")
            parts.append(f"{v}={got}" + ("" if got == want else f"(truth {want})"))
        where = f"item {c.index}" if c.index >= 0 else "no item"
        print(
            f"  frames {c.segment[0]}-{c.segment[1]} ({where}, {c.camera_frames} camera frames): "
            + " ".join(parts),
            file=stream,
        )
