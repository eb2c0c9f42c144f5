"""What a side of `beyond up` runs: its services (less those skipped, run elsewhere, or left
out), each one's options and the source, refused before anything starts when they are bad."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from beyond_self.cognition.paths import DEMO_RECORDING
from beyond_self.cognition.pose.video import Video
from beyond_self.commands.ros2 import ros2_options
from beyond_self.commands.up_options import out_dir_env
from beyond_self.commands.up_side import fleet_env, monitor_name, secure_router
from beyond_self.commands.up_watch import EventLines, log_line
from beyond_self.core.errors import unknown
from beyond_self.runtime.bus.config import BusConfig
from beyond_self.runtime.recording.reader import require_mcap
from beyond_self.schemas.keys import check_name
from beyond_self.services.deployment import Deployment
from beyond_self.services.options import load_options
from beyond_self.services.registry import PROFILES, SERVICES


def service_names(values: list[str]) -> list[str]:
    """Service names given to --skip or --without (also comma-separated), each a known one."""
    names = [n.strip() for v in values for n in v.split(",") if n.strip()]
    for name in names:
        if name not in SERVICES:
            raise unknown("service", name, list(SERVICES))
    return names


def wait_list(values: list[str]) -> list[str]:
    names = [n.strip() for v in values for n in v.split(",") if n.strip()]
    for name in names:
        check_name("service", name)
    return names


def awaited_elsewhere(args: argparse.Namespace) -> dict[str, str]:
    """The services this side's source waits for that run elsewhere: name -> the option that
    says so (--skip, --wait-for)."""
    skipped = [n for n in service_names(args.skip) if n in PROFILES[args.profile]]
    named = {n: "--wait-for" for n in wait_list(args.wait_for)}
    return named | dict.fromkeys(skipped, "--skip")


def _source(args: argparse.Namespace) -> dict[str, Any]:
    if args.recording is not None:
        require_mcap(args.recording)  # refused here, on one line, before anything starts
        return {"recording": str(args.recording)}
    if args.log is not None:
        return {"log": str(args.log)}
    if args.live_source is not None:
        return {"plugin": args.live_source}
    if args.video is not None or args.camera is not None:
        # refused here, on one line, before anything starts: a file that is no video, a
        # camera that does not open (the ingest opens it again once the pipeline is up)
        Video(args.video, camera=args.camera).close()
        return {"video": str(args.video)} if args.video is not None else {"camera": args.camera}
    return {}


def service_options(args: argparse.Namespace, names: list[str]) -> tuple[dict[str, Any], bool]:
    """Each service's options (the config file's, then the command line's), and whether the
    source replays something finite (its services then follow the recording's clock). Without
    a source anywhere, the demo recording is the source."""
    file_options = load_options(args.config)
    options: dict[str, dict[str, Any]] = {n: dict(file_options.get(n, {})) for n in names}
    source = _source(args)
    replayed = "log" in source or "recording" in source
    if "ingest" in names:
        if not source and not any(k in options["ingest"] for k in ("recording", "log", "plugin")):
            source = {"recording": str(DEMO_RECORDING)}
            replayed = True
        options["ingest"].update(source)
        options["ingest"].setdefault("rate", args.rate)
    if "reasoner" in names and "objects" in service_names(args.without):
        # no object segmenter anywhere: the reasoner must not wait for one
        options["reasoner"].setdefault("objects", False)
    check_inputs(options)
    return options, replayed


def check_inputs(options: dict[str, dict[str, Any]]) -> None:
    """A hand log or gesture models the services would refuse are refused here, before
    anything starts (one line, exit status 2), exactly as `beyond analyse` refuses them."""
    from beyond_self.cognition.gestures.default_models import pipeline_models
    from beyond_self.cognition.gestures.logs import hand_log_stream

    ingest = options.get("ingest", {})
    scale = ingest.get("scale", 0.001)
    if ingest.get("log") and isinstance(scale, int | float):  # a bad scale: the options' check
        hand_log_stream(Path(str(ingest["log"])), float(scale))
    models = options.get("gestures", {}).get("models")
    if models:
        pipeline_models(str(models))


def deployment(
    args: argparse.Namespace, config: BusConfig, lines: EventLines
) -> tuple[Deployment, bool]:
    """The side's Deployment, and whether it replays a finite source."""
    skip, without = service_names(args.skip), service_names(args.without)
    names = [n for n in PROFILES[args.profile] if n not in skip and n not in without]
    if args.ros2:
        names.append("ros2")
    options, replayed = service_options(args, names)
    if args.ros2:
        options["ros2"].update(ros2_options(args))
    router = None
    if config.secure is not None:
        router, local = secure_router(config, names, args.profile)
        # this side's router links elsewhere; its processes are clients of it
        config = config.with_(connect=(local,) if local else None, routers=())
    side = Deployment(
        config,
        names,
        options=options,
        env=fleet_env(config, args.profile) | out_dir_env(args),
        wait_for=wait_list(args.wait_for) + [n for n in skip if n in PROFILES[args.profile]],
        watcher=monitor_name(args.profile),
        clock="recording" if replayed else "wall",
        router=router,
        log=log_line,
        on_stuck=lambda n, why: lines.emit(f"service {n} is stuck ({why}); stopping it"),
        stop_on_signals=True,
        shards=args.shards,
        # what dies is started again: said on stderr, beside the services' own logs (stdout
        # holds the gesture lines, the same as beyond analyse prints)
        on_restart=lambda n, what: print(f"[up] {n}: {what}", file=sys.stderr, flush=True),
    )
    return side, replayed
