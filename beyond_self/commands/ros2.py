"""`beyond ros2`: the ROS 2 face of a deployment: `export` writes a recording as a rosbag2 bag
(runtime.ros2_bag), `bridge` joins a running deployment to a ROS 2 graph over rmw_zenoh
(services.ros2_bridge)."""

from __future__ import annotations

import argparse
from pathlib import Path

from beyond_self.commands import argtypes

HELP = "ROS 2: export a recording as a rosbag2 bag, or bridge a deployment to rmw_zenoh"


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


def run(args: argparse.Namespace) -> int:
    from beyond_self.runtime.recording import require_mcap
    from beyond_self.runtime.ros2_bag import export

    if args.ros2_command == "export":
        require_mcap(args.recording)
        stats = export(args.recording, Path(args.output), robot=args.as_robot)
        print(f"{args.output}: {stats.messages} messages")
        for key, n in sorted(stats.skipped.items()):
            print(f"  not exported (no standard ROS 2 type): {key} ({n} messages)")
        return 0
    return 2
