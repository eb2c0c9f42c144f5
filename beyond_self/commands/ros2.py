"""`beyond ros2`: the ROS 2 face of a deployment: `export` writes a recording as a rosbag2 bag
(runtime.ros2.bag), `bridge` joins a running deployment to a ROS 2 graph over DDS or rmw_zenoh
(services.ros2_bridge)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from beyond_self.commands import argtypes
from beyond_self.core.errors import InputError
from beyond_self.runtime import outputs
from beyond_self.runtime.bus.cliargs import add_bus_arguments, config_from_args
from beyond_self.runtime.ros2 import rmw
from beyond_self.runtime.ros2.rmw import RMWS
from beyond_self.schemas.keys import DEFAULT_ROBOT
from beyond_self.schemas.ros2 import DEFAULT_CONNECT, Ros2Topics

HELP = "ROS 2: export a recording as a rosbag2 bag, or bridge a deployment to a ROS 2 graph"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="ros2_command", metavar="ACTION", required=True)
    export = sub.add_parser("export", help="write a recording as a rosbag2 bag (MCAP, CDR)")
    export.add_argument("recording", type=Path, help="an MCAP recording of ours (or a bag)")
    argtypes.add_output(export, "the bag folder to create", folder=True, required=True)
    export.add_argument(
        "--as-robot",
        metavar="NAME",
        help="the robot namespace of the topics (default: the recording's robot)",
    )

    bridge = sub.add_parser(
        "bridge", help="join a running deployment to a ROS 2 graph (DDS or rmw_zenoh) until SIGINT"
    )
    add_ros2_arguments(bridge, flag=False)
    bridge.add_argument(
        "--out-dir",
        type=Path,
        default=None,
        help="where the bridge logs the sentences it said (a restart says none again; default: "
        f"ros2/ under {outputs.DESCRIPTION})",
    )
    add_bus_arguments(bridge)


def add_ros2_arguments(parser: argparse.ArgumentParser, *, flag: bool) -> None:
    """The ROS 2 options, the same for `beyond ros2 bridge` and `beyond up --ros2`."""
    group = parser.add_argument_group("ROS 2", "joining a ROS 2 graph over DDS or rmw_zenoh")
    if flag:
        group.add_argument(
            "--ros2",
            action="store_true",
            help="also run the ROS 2 bridge: descriptions, skeleton and cameras as standard "
            "ROS 2 topics under /ROBOT (docs/how-to/ros2.md)",
        )
    group.add_argument(
        "--ros2-rmw",
        choices=RMWS,
        default=None,
        help="the middleware (default: as $RMW_IMPLEMENTATION says: rmw_zenoh_cpp is zenoh, "
        "unset or a DDS rmw is dds, ROS 2's default)",
    )
    group.add_argument(
        "--ros2-connect",
        metavar="ENDPOINT",
        default=DEFAULT_CONNECT,
        help=f"rmw_zenoh's router (default {DEFAULT_CONNECT}; zenoh only)",
    )
    group.add_argument(
        "--ros2-topic",
        action="append",
        default=[],
        metavar="STREAM=TOPIC",
        help="publish a stream on another topic (streams: description, skeleton, camera, "
        "camera_compressed, person_camera; a relative topic goes under /ROBOT; repeat)",
    )
    group.add_argument(
        "--ros2-domain",
        type=argtypes.count(0, 232, "ROS 2 domain"),
        default=None,
        metavar="N",
        help="ROS 2 domain id (default $ROS_DOMAIN_ID, else 0)",
    )


def ros2_options(args: argparse.Namespace) -> dict[str, Any]:
    """The bridge service's options (services.ros2_bridge) from the ROS 2 arguments."""
    options: dict[str, Any] = {
        "connect": args.ros2_connect,
        "middleware": rmw.choose(args.ros2_rmw),
    }
    renamed = {}
    for item in args.ros2_topic:
        stream, sep, topic = item.partition("=")
        if not sep or not topic:
            raise InputError(f"--ros2-topic expects STREAM=TOPIC; got {item!r}")
        renamed[stream] = topic
    if renamed:
        Ros2Topics(DEFAULT_ROBOT, renamed)  # refused here, on one line, before anything starts
        options["topics"] = renamed
    if args.ros2_domain is not None:
        options["domain_id"] = int(args.ros2_domain)
    return options


def run(args: argparse.Namespace) -> int:
    if args.ros2_command == "bridge":
        from beyond_self.services.ros2_bridge import Ros2Bridge

        Ros2Bridge.main(  # its options parsed here: the service reads no command line
            argv=(),
            config=config_from_args(args),
            out_dir=None if args.out_dir is None else str(args.out_dir),
            **ros2_options(args),
        )
    from beyond_self.runtime.recording.reader import require_mcap
    from beyond_self.runtime.ros2.bag_export import export

    if args.ros2_command == "export":
        require_mcap(args.recording)
        stats = export(args.recording, Path(args.output), robot=args.as_robot)
        print(f"{args.output}: {stats.messages} messages")
        for key, n in sorted(stats.skipped.items()):
            print(f"  not exported (no standard ROS 2 type): {key} ({n} messages)")
        return 0
    return 2
