"""`beyond analyse RECORDING|LOG`: the whole pipeline over a recording, offline, in one process.

No bus, no services: the skeleton and camera streams are read in recording order and go through
the same library classes the services run (cognition.episodes), with the same options. It
prints the lines `beyond up` prints for the same recording: the specification a run on the bus,
at any rate and under any load, must equal. A damaged recording is analysed as far as it is
readable, and what was lost is said in one line (exit 2), as `inspect`, `replay` and `up` say it.
A YARP hand log is read exactly as `beyond up --log` plays it.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from beyond_self.cognition.bn import learn_network, load_model, synthetic_dataset
from beyond_self.cognition.episodes.offline import (
    CameraInput,
    OfflineRun,
    SkeletonInput,
    analyse_stream,
)
from beyond_self.cognition.gestures.default_models import default_models, pipeline_models
from beyond_self.cognition.gestures.logs import hand_log_stream
from beyond_self.cognition.vision.clusters import ClusterModel
from beyond_self.commands import argtypes
from beyond_self.core.errors import InputError
from beyond_self.runtime.recording.damage import Losses
from beyond_self.runtime.recording.images import image_from_message
from beyond_self.runtime.recording.reader import (
    inspect_recording,
    read_recording,
    require_mcap,
    scan_recording,
)
from beyond_self.runtime.recording.replay import Cue, looped, recorded_cues
from beyond_self.runtime.recording.robots import recorded_robot
from beyond_self.schemas import CameraFrame, CompressedCameraFrame, SkeletonFrame
from beyond_self.schemas.keys import TABLETOP_CAMERA, split_key
from beyond_self.services.options import check_options, load_options
from beyond_self.services.registry import service_class

HELP = "run the pipeline's logic over a recording offline and print what `beyond up` prints"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "recording", type=Path, help="MCAP recording (skeleton and camera), or a YARP hand log"
    )
    parser.add_argument("--config", help="YAML/JSON file with per-service options (as for up)")
    parser.add_argument("--json", action="store_true", help="one JSON object per gesture")
    parser.add_argument(
        "--robot",
        type=argtypes.robot_name,
        help="the robot whose part of a fleet's recording to analyse (a recording of one robot "
        "needs none)",
    )
    argtypes.add_ros2_topic(parser)


def _inputs(
    path: Path,
    hand: str,
    torso: str,
    losses: Losses | None = None,
    robot: str | None = None,
    roles: dict[str, str] | None = None,
    notes: list[str] | None = None,
) -> Iterator[SkeletonInput | CameraInput]:
    """The skeleton and camera frames of a recording, as the ingest plays them: what does not
    decode or does not move forward in time is dropped and counted in `losses`
    (runtime.recording.damage), the same frames every command drops; of a fleet's recording,
    robot `robot`'s (runtime.fleet.recorded_robot). Of a ROS 2 bag, `roles` maps topics
    (runtime.ros2.topics); what the bag holds that is not read is added to `notes`."""
    tally = losses if losses is not None else Losses(str(path))
    info = scan_recording(path, roles)
    argtypes.check_ros2_roles(roles or {}, info)
    if notes is not None:
        notes.extend(info.notes)
    source = recorded_robot(info, robot)

    def ours(key: str) -> str | None:
        split = split_key(key)
        return key if split is not None and split[0] == source else None

    cues = recorded_cues(read_recording(path, losses=tally, ros2_roles=roles), ours, tally)
    return inputs_of(cues, hand, torso)


def inputs_of(cues: Iterable[Cue], hand: str, torso: str) -> Iterator[SkeletonInput | CameraInput]:
    """The pipeline's inputs in cues (a recording's, or a looped one's)."""
    for cue in cues:
        split = split_key(cue.key)
        if split is None or cue.message is None:
            continue
        msg = cue.message
        if isinstance(msg, SkeletonFrame):
            joint = msg.joints.get(hand)
            if joint is None:
                raise InputError(
                    f"skeleton frame {msg.frame} has no joint {hand!r}; joints: "
                    f"{', '.join(list(msg.joints)[:8]) or 'none'}"
                )
            body = msg.joints.get(torso)
            yield SkeletonInput(
                msg.header.stamp, msg.frame, joint.position, body.position if body else None
            )
        elif isinstance(msg, CameraFrame | CompressedCameraFrame) and split[1] in TABLETOP_CAMERA:
            yield CameraInput(msg.header.stamp, msg.header.seq, image_from_message(msg))


def looped_inputs(
    path: Path, passes: int, hand: str = "right_hand", torso: str = "torso"
) -> Iterator[SkeletonInput | CameraInput]:
    """The inputs of `passes` passes of a recording, each restamped after the last, as the
    ingest plays it with `loop: true` (runtime.recording.replay.looped): what `up` over a looped
    source
    must tell."""
    info = inspect_recording(path)
    if info.start is None or info.end is None:
        return iter(())
    made = 0

    def one_pass() -> Iterator[Cue]:
        nonlocal made
        made += 1
        return recorded_cues(read_recording(path)) if made <= passes else iter(())

    return inputs_of(looped(one_pass, loop=True, span=(info.start, info.end)), hand, torso)


def default_run(inputs: Iterable[SkeletonInput | CameraInput]) -> OfflineRun:
    """The offline analysis with the default models (no --config): what `up` prints."""
    return analyse_stream(
        inputs,
        gesture_models=default_models(),
        clusters=ClusterModel.load(),
        network=learn_network(synthetic_dataset()),
    )


def log_inputs(path: Path, scale: float) -> Iterator[SkeletonInput]:
    """A hand log's frames as the ingest service publishes them (one joint, no torso)."""
    stamps, positions = hand_log_stream(path, scale)
    for i, (stamp, xyz) in enumerate(zip(stamps, positions, strict=True)):
        yield SkeletonInput(int(stamp), i + 1, (float(xyz[0]), float(xyz[1]), float(xyz[2])), None)


def _options(config: str | None) -> dict[str, dict[str, Any]]:
    file_options = load_options(config)
    names = ("ingest", "gestures", "objects", "reasoner", "describer")
    return {n: check_options(n, service_class(n), dict(file_options.get(n, {}))) for n in names}


def is_hand_log(path: Path) -> bool:
    """A YARP hand log (a folder holding data.log, or a data.log), not an MCAP recording."""
    return (path / "data.log").is_file() if path.is_dir() else path.name == "data.log"


def run(args: argparse.Namespace) -> int:
    losses = Losses(str(args.recording))
    o = _options(args.config)
    g, ob, r, d = o["gestures"], o["objects"], o["reasoner"], o["describer"]
    if is_hand_log(args.recording):
        inputs: Iterable[SkeletonInput | CameraInput] = log_inputs(
            args.recording, float(o["ingest"].get("scale", 0.001))
        )
    else:
        roles = argtypes.ros2_roles(args)
        require_mcap(args.recording, roles)
        notes: list[str] = []
        inputs = _inputs(
            args.recording,
            g.get("hand_joint", "right_hand"),
            g.get("torso_joint", "torso"),
            losses,
            args.robot,
            roles,
            notes,
        )
        for text in notes:
            argtypes.note(args, text)
    models = pipeline_models(g.get("models"))
    network = load_model(Path(r["model"])) if r.get("model") else learn_network(synthetic_dataset())
    emit = None if args.json else (lambda line: print(line, flush=True))
    result = analyse_stream(
        inputs,
        gesture_models=models,
        clusters=ClusterModel.load(ob.get("clusters")),
        network=network,
        nbest=int(d.get("nbest", 5)),
        legacy_offset=bool(d.get("legacy_offset", False)),
        lead_s=float(ob.get("lead_s", 0.3)),
        fps=ob.get("fps"),
        camera_deadline_s=float(ob.get("deadline_s", 5.0)),
        objects_deadline_s=float(r.get("deadline_s", 30.0)),
        on_line=emit,
    )
    if args.json:
        for out in result.outcomes:
            print(
                json.dumps(
                    {
                        "segment_id": out.segment_id,
                        "frame": out.frame,
                        "action_belief": out.prediction.action_belief,
                        "evidence": out.prediction.evidence,
                        "sentences": result.sentences.get(out.segment_id, []),
                    }
                )
            )
    if losses.any:  # what was readable is analysed above; what was not, in one line (exit 2)
        raise InputError(losses.line())
    return 0
