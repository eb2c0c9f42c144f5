"""`beyond up`'s options, grouped by what each sets up: the source, the services, the run,
the side among others; then the ROS 2 bridge's and the bus's, as every command has them."""

from __future__ import annotations

import argparse
from pathlib import Path

from beyond_self.cognition.pose.video import CAMERA_INDEX_MAX
from beyond_self.commands import argtypes
from beyond_self.commands.ros2 import add_ros2_arguments
from beyond_self.runtime import outputs
from beyond_self.runtime.bus.cliargs import add_bus_arguments
from beyond_self.services.registry import PROFILES

DEFAULT_TIMEOUT = 120.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """`beyond up`'s command line, in the order `--help` lists it."""
    add_source_options(parser)
    add_service_options(parser)
    add_run_options(parser)
    add_side_options(parser)
    add_ros2_arguments(parser, flag=True)
    add_bus_arguments(parser)
    parser.description = (
        "Start the services of --profile, each in its own process, on the bus (default: Zenoh "
        "peers on loopback), the source last, once the services it feeds are alive. Pipeline "
        "events (recognised action, anticipated effect, description) go to stdout, with a live "
        "view on a terminal; service logs go to stderr. With a source, `up` exits once the "
        "source has ended and every gesture has its final description; Ctrl-C stops everything. "
        "A service that dies is started again; one that keeps dying is given up on, and `up` "
        "ends. The services write under --out-dir, never in the current folder."
    )
    parser.epilog = (
        "Two machines: `beyond router` and --profile workstation --connect tcp/127.0.0.1:7447 "
        "on one, --profile robot --connect tcp/WORKSTATION:7447 on the other; either side may "
        "start first. A fleet: --profile fleet-workstation --robots 'lab-*' --robot ws-1, and on "
        "each robot --profile fleet-robot --wait-for gestures,objects,reasoner,describer. "
        "--secure DIR checks every certificate the side needs, then starts the side's own "
        "router, which its processes join as clients. "
        "Every service dies with `up`, however `up` ends (SIGKILL too). A second `up` for a "
        "robot whose services are on the bus already says so in one line and exits 2: stop the "
        "first, or give the second another --robot. Exit status: 0 done; 1 a failure or a "
        "timeout; 2 bad input (a damaged recording, a second up); 3 done, but the run lost "
        "gestures (cut: their frames were lost) or sensor frames (dropped as stale), as its "
        "summary says."
    )


def add_source_options(parser: argparse.ArgumentParser) -> None:
    """What the pipeline watches: one source at most (none: the demo recording)."""
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--recording", type=Path, help="MCAP recording to replay into the pipeline")
    source.add_argument("--log", type=Path, help="YARP hand log (the article's data.log)")
    source.add_argument("--live-source", metavar="MODULE:FUNCTION", help="live source plug-in")
    source.add_argument(
        "--video",
        type=Path,
        metavar="FILE",
        help="watch a person in a video file, live at its own pace, through the pose model "
        "(the camera extra); ends with the file",
    )
    source.add_argument(
        "--camera",
        type=argtypes.count(0, CAMERA_INDEX_MAX, "camera index"),
        metavar="INDEX",
        help="watch a person through a camera (OpenCV's index: 0 is /dev/video0) with the pose "
        "model (the camera extra)",
    )


def add_service_options(parser: argparse.ArgumentParser) -> None:
    """Which services this side runs, and with which options."""
    parser.add_argument("--config", help="YAML/JSON file with per-service options")
    parser.add_argument(
        "--profile",
        choices=list(PROFILES),
        default="all",
        help="which services: all (default: one machine), robot or workstation (a side of two "
        "machines), fleet-robot or fleet-workstation (a side of a fleet)",
    )
    parser.add_argument(
        "--skip",
        action="append",
        default=[],
        metavar="SERVICE",
        help="do not start this service here: it runs elsewhere (e.g. your own speech "
        "synthesizer), and the others still expect it (the source waits for it)",
    )
    parser.add_argument(
        "--without",
        action="append",
        default=[],
        metavar="SERVICE",
        help="the deployment has no such service: it is not started nor waited for, and the "
        "services that would use it are told (--without objects: no object evidence)",
    )


def add_run_options(parser: argparse.ArgumentParser) -> None:
    """How the run goes: its pace, its view, its state, where it writes, its timeout."""
    parser.add_argument(
        "--rate",
        type=argtypes.rate,
        default=1.0,
        help="speed factor of a replayed source (default 1; 0: as fast as possible)",
    )
    parser.add_argument("--no-live", action="store_true", help="no live view, event lines only")
    parser.add_argument(
        "--fresh",
        action="store_true",
        help="start over: clear the state an unfinished run of this side left (by default the "
        "same command goes on from it)",
    )
    add_out_dir(parser)
    parser.add_argument(
        "--foxglove",
        nargs="?",
        type=argtypes.port,
        const=8765,
        metavar="PORT",
        help="also serve the bus to Foxglove on ws://localhost:PORT (default 8765)",
    )
    parser.add_argument(
        "--timeout",
        type=argtypes.seconds(),
        default=None,
        help="give up when nothing has moved S seconds after start-up, or S seconds after the "
        f"source ended (default {DEFAULT_TIMEOUT:.0f} with a source or --until-stream-end, else "
        "never); a source's silence while it runs never counts",
    )


def add_side_options(parser: argparse.ArgumentParser) -> None:
    """This side among others: what runs elsewhere, a fleet's robots, when it ends."""
    parser.add_argument(
        "--wait-for",
        action="append",
        default=[],
        metavar="NAME[,NAME...]",
        help="services elsewhere (e.g. the workstation's reasoner) the source waits for too",
    )
    parser.add_argument(
        "--robots",
        metavar="PATTERN",
        help="serve every robot PATTERN matches, e.g. 'lab-*' (a fleet's workstation: "
        "--profile fleet-workstation; default: the one robot --robot)",
    )
    parser.add_argument(
        "--standby",
        metavar="PATTERN",
        help="also serve the robots PATTERN matches, but only while no other workstation "
        "does (failover: takes over another workstation's robots when it dies); with --robots",
    )
    parser.add_argument(
        "--shards",
        type=argtypes.shards,
        default=1,
        metavar="N",
        help="with --robots: run each service as N processes (auto: one per core this process "
        "may use), each serving the robots a stable hash of their names gives it (default 1)",
    )
    parser.add_argument(
        "--until-stream-end",
        action="store_true",
        help="exit once the (remote) source has ended and every gesture is described",
    )


def add_out_dir(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--out-dir",
        type=argtypes.output_dir,
        metavar="DIR",
        help=f"where the services write (the speech WAVs and speech.log in DIR/speech; default: "
        f"{outputs.DESCRIPTION})",
    )


def out_dir_env(args: argparse.Namespace) -> dict[str, str]:
    """The services' output folder (runtime.outputs), when --out-dir names one."""
    out = getattr(args, "out_dir", None)
    return {outputs.OUT_DIR_VAR: str(out.resolve())} if out is not None else {}
