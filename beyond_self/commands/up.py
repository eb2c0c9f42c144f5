"""`beyond up`: the whole pipeline, every service in its own process, on one machine or one side.

This module is the command line and the terminal around a `services.deployment.Deployment`, which
starts and supervises the processes: the options, the live view, the event lines on stdout
(service logs on stderr) and the exit status. A run with a source ends once the source has ended
and every gesture has its final description; `--timeout` bounds start-up and the tail, never a
running source's silence. Sides, fleets and the secure bus: docs/concepts/deployment.md,
fleets.md and security.md.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.live import Live

from beyond_self.cognition.paths import DEMO_RECORDING
from beyond_self.cognition.pose.video import CAMERA_INDEX_MAX, Video
from beyond_self.commands import argtypes
from beyond_self.commands.ros2 import add_ros2_arguments, ros2_options
from beyond_self.core.errors import InputError, unknown
from beyond_self.live_view import render
from beyond_self.monitor import PipelineMonitor
from beyond_self.runtime import outputs
from beyond_self.runtime.bus.cliargs import add_bus_arguments, config_from_args
from beyond_self.runtime.bus.config import BusConfig
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.process import exit_process
from beyond_self.runtime.recording.reader import require_mcap
from beyond_self.runtime.resilience.run_state import RunState, run_state_root
from beyond_self.schemas.keys import check_name
from beyond_self.services.deployment import Deployment, Ending
from beyond_self.services.options import load_options
from beyond_self.services.registry import PROFILES, SERVICES

HELP = "start the pipeline's services as separate processes and watch them"
DEFAULT_TIMEOUT = 120.0
LOST = 3  # exit status of a run that lost gestures or sensor frames (its summary says which)
ALIVE_QUERY_S = 2.0  # how long the services already on the bus have to answer
HINT_S = 5.0  # how often `up` says which service it still waits for, and how to start it


def add_arguments(parser: argparse.ArgumentParser) -> None:
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
        "--until-stream-end",
        action="store_true",
        help="exit once the (remote) source has ended and every gesture is described",
    )
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


def run(args: argparse.Namespace) -> int:
    config = config_from_args(args)
    if args.robots is not None or args.standby is not None:
        check_fleet_profile(args.profile)
    if args.profile.endswith("workstation") and _mode_unset(args, config):
        config = config.with_(mode="client")
    if config.secure is not None and config.identity is None:  # the monitor is the side's
        config = config.with_(identity=side_identity(args.profile, config.robot))
    try:
        status = asyncio.run(up(args, local_group(config)))
    except InputError as exc:  # bad input (a damaged recording...): one line, as every command
        print(f"beyond up: error: {exc}", file=sys.stderr)
        status = 2
    # every service is stopped and the session closed: leave without the interpreter's teardown,
    # which can abort (SIGABRT) a process whose Zenoh native threads are up (exit_process)
    exit_process(status)


def secure_router(
    config: BusConfig, names: list[str], profile: str
) -> tuple[list[str], str | None]:
    """On a secure bus every side runs its own router: check every certificate this side needs
    (one line naming the file, before anything starts) and return the router's command, and
    where this side's processes reach it when it is not the default (None). Given endpoints
    elsewhere (the workstation's router), this side's router links to them with the side's
    certificate, and this side's processes stay on their own router, so a robot's pipeline
    keeps running when the network between the machines fails; that router listens on
    loopback only, on the bus's port (7447 unless told) if free, else on a free port: a second
    workstation of a fleet on the first one's host links to the first one's router there."""
    from beyond_self.runtime.security import keystore
    from beyond_self.runtime.security.secure import router_listen

    assert config.secure is not None
    remote = list(config.connect or ()) + list(config.routers)
    fleet = fleet_side(profile)  # one certificate for the side: its robot's, or its host's
    if fleet:
        identity = str(config.identity)
    elif remote:
        identity = side_identity(profile, config.robot)
    else:
        identity = "router"
    for name in [*([] if fleet else names), str(config.identity), identity]:
        keystore.check(config.secure, name)
    command = ["router", "--secure", str(config.secure), "--identity", identity]
    if not remote:
        # on the rendezvous port; everything on one machine (`--profile all`) stays on
        # loopback, a side meant for other machines listens on every interface
        command += ["--listen", router_listen(config.port, loopback=profile == "all")]
        return command, None
    local = router_listen(loopback_port(config.port), loopback=True)
    command += ["--listen", local] + [a for e in remote for a in ("--connect", e)]
    return command, local


def loopback_port(preferred: int) -> int:
    """`preferred` if nothing listens there on this machine, else a port the system picks."""
    import socket

    for port in (preferred, 0):
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
            try:
                probe.bind(("127.0.0.1", port))
            except OSError:
                continue
            found: int = probe.getsockname()[1]
            return found
    raise InputError("no free TCP port on 127.0.0.1 for this side's router")


def side_identity(profile: str, robot: str) -> str:
    """The certificate of a side's monitor and router: the robot's or the workstation's. A
    fleet's side is its own name (`--robot lab-1`, `--robot ws-1`): the certificate `beyond
    keys add` bound to that robot, or to the robots that workstation is granted, which its
    router and every process it starts present (fleet_env)."""
    if fleet_side(profile):
        return robot
    return "robot" if profile.endswith("robot") else "workstation"


def fleet_side(profile: str) -> bool:
    return profile.startswith("fleet-")


def fleet_env(config: BusConfig, profile: str) -> dict[str, str]:
    """On a secure fleet every process of the side presents the side's certificate, bound to
    its robots (elsewhere each service presents its own, bound to the deployment's robot)."""
    if config.secure is None or not fleet_side(profile) or config.identity is None:
        return {}
    return {"BEYOND_ZENOH_IDENTITY": config.identity}


def check_fleet_profile(profile: str) -> None:
    """A workstation's services for every robot `--robots` matches: only those that can serve
    many robots from one process (not a robot's source or voice)."""
    from beyond_self.services.registry import service_class

    single = [n for n in PROFILES[profile] if not service_class(n).fleet]
    if single:
        raise InputError(
            f"--robots: profile {profile} has {', '.join(single)}, which serve one robot; "
            "use --profile fleet-workstation"
        )


def _mode_unset(args: argparse.Namespace, config: BusConfig) -> bool:
    return (
        getattr(args, "mode", None) is None
        and not os.environ.get("BEYOND_ZENOH_MODE")
        and config.config_file is None
    )


def local_group(config: BusConfig) -> BusConfig:
    """In peer mode, endpoints given to connect to are routers linked to this machine's group,
    not a replacement of it: the services `up` starts keep meeting on loopback."""
    if config.mode == "peer" and config.connect is not None:
        return config.with_(connect=None, routers=config.routers + config.connect)
    return config


def monitor_name(profile: str) -> str:
    """Liveliness name of `up`'s own monitor: one per side, so two sides never mistake each
    other's monitor for their own."""
    return "monitor" if profile == "all" else f"monitor-{profile}"


def wait_list(values: list[str]) -> list[str]:
    names = [n.strip() for v in values for n in v.split(",") if n.strip()]
    for name in names:
        check_name("service", name)
    return names


class EventLines:
    """Where pipeline events go: above the live view while it runs, else plain stdout lines."""

    def __init__(self) -> None:
        self.live: Live | None = None

    def emit(self, line: str) -> None:
        if self.live is not None:
            self.live.console.print(line, markup=False, highlight=False)
        else:
            print(line, flush=True)


def log_line(name: str, line: str) -> None:
    print(f"[{name}] {line}", file=sys.stderr, flush=True)


def service_names(values: list[str]) -> list[str]:
    """Service names given to --skip or --without (also comma-separated), each a known one."""
    names = [n.strip() for v in values for n in v.split(",") if n.strip()]
    for name in names:
        if name not in SERVICES:
            raise unknown("service", name, list(SERVICES))
    return names


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
        # what dies is started again: said on stderr, beside the services' own logs (stdout
        # holds the gesture lines, the same as beyond analyse prints)
        on_restart=lambda n, what: print(f"[up] {n}: {what}", file=sys.stderr, flush=True),
    )
    return side, replayed


async def up(args: argparse.Namespace, config: BusConfig) -> int:
    lines = EventLines()
    side, _ = deployment(args, config, lines)
    finite = "ingest" in side.services or args.until_stream_end  # ends when its source does
    timeout = args.timeout
    if timeout is None and ("ingest" in side.services or finite):
        timeout = DEFAULT_TIMEOUT
    state = run_state(args, side)
    # the processes start now, held off the bus: their interpreters and imports overlap the
    # session's opening and the look for another `up`, which refuses before any joins
    await side.prepare()
    try:
        bus = await side.open()
        running = await already_up(side, bus)
    except BaseException:
        await side.stop()
        raise
    if running:
        await side.stop()
        raise InputError(
            f"robot {side.config.robot!r} already has {', '.join(running)} on the bus (another "
            "beyond up?); stop it first, or give this one another --robot"
        )
    if said := state.begin(run_command(args, side), fresh=args.fresh):
        print(f"[up] {said}", file=sys.stderr, flush=True)
    pipeline = PipelineMonitor.of(side, bus, lines.emit, state)
    loop = asyncio.get_running_loop()
    hints: list[asyncio.Task[None]] = []
    try:
        if args.foxglove:  # imported only when asked for: the SDK is not free to load
            from beyond_self.runtime.foxglove.bridge import start_in_background

            side.attach(await start_in_background(bus, args.foxglove))
            lines.emit(f"Foxglove: open a WebSocket connection to ws://localhost:{args.foxglove}")
        pipeline.start()
        await side.start()
        if not side.exited():
            lines.emit(f"pipeline up: {', '.join(side.services)} on robot {side.config.robot!r}")
        hints.append(loop.create_task(say_what_is_awaited(bus, awaited_elsewhere(args))))
        ending = await watch(side, pipeline, lines, timeout, finite, live=not args.no_live)
        await pipeline.last_health()  # what was dropped since the last report counts too
    finally:
        for task in hints:
            task.cancel()
        pipeline.stop()
        codes = await side.stop()
    lines.emit(pipeline.summary())
    if side.restarts:
        counts = ", ".join(f"{n} {r.count}" for n, r in side.restarts.items() if r.count)
        print(f"restarts: {counts or 'none'}", file=sys.stderr)
    err_codes = ", ".join(f"{n} {c}" for n, c in codes.items())
    print(f"services stopped (exit codes: {err_codes})", file=sys.stderr)
    if failed := side.unclean():
        lines.emit(f"services that did not stop cleanly: {failed}")
        return 1
    if ending.reason == "done":  # complete: the same command again starts over
        state.clear()
    end = pipeline.stream_end
    return exit_status(ending, end.damage if end is not None else "", pipeline.losses())


def run_state(args: argparse.Namespace, side: Deployment) -> RunState:
    """The side's state on this machine (runtime.resilience.run_state), given to its services."""
    out = getattr(args, "out_dir", None)
    root = run_state_root(out.resolve() if out is not None else None)
    state = RunState(root, side.config.robot, side.watcher or "up", side.services)
    side.env.update(state.env())
    return state


# what does not change a run's results: the same command but for these goes on from its state
PRESENTATION = frozenset(("fresh", "no_live", "timeout", "foxglove", "func", "command"))


def run_command(args: argparse.Namespace, side: Deployment) -> str:
    """The run's identity: the side's services and every option that shapes its results, the
    source's path resolved."""
    options = {
        k: str(Path(v).resolve()) if k in ("recording", "log", "video") and v else v
        for k, v in sorted(vars(args).items())
        if k not in PRESENTATION and not callable(v)
    }
    everything = {"robot": side.config.robot, "services": side.services, **options}
    return json.dumps(everything, sort_keys=True, default=str)


def exit_status(ending: Ending, damage: str, lost: list[str]) -> int:
    """0, or 1 (a failure, a timeout), InputError (2: a damaged source), or LOST (the run lost
    gestures or sensor frames, which the summary said)."""
    if not ending.ok:
        return 1
    if damage:  # the readable part was played and described; what was lost, as analyse says it
        raise InputError(damage)
    return LOST if lost else 0


def awaited_elsewhere(args: argparse.Namespace) -> dict[str, str]:
    """The services this side's source waits for that run elsewhere: name -> the option that
    says so (--skip, --wait-for)."""
    skipped = [n for n in service_names(args.skip) if n in PROFILES[args.profile]]
    named = {n: "--wait-for" for n in wait_list(args.wait_for)}
    return named | dict.fromkeys(skipped, "--skip")


async def say_what_is_awaited(
    bus: Bus,
    awaited: dict[str, str],
    period: float = HINT_S,
    say: Callable[[str], None] | None = None,
) -> None:
    """Every `period` s, until each service of `awaited` is on the bus, say on stderr which are
    not and how to start one: a side waiting on a service nobody started waits in silence."""
    say = say or (lambda text: print(f"[up] {text}", file=sys.stderr, flush=True))
    robot = bus.keys.robot
    while awaited:
        await asyncio.sleep(period)  # a timer for the terminal: nothing waits on it
        found = await bus.live_tokens(bus.keys.alive("*"), timeout=ALIVE_QUERY_S)
        alive = {key.rsplit("/", 1)[-1] for key in found}
        awaited = {n: why for n, why in awaited.items() if n not in alive}
        for name, why in awaited.items():
            say(
                f"waiting for {name} ({why}: it runs elsewhere); start it on this bus, e.g. "
                f"`beyond service {name} --robot {robot}`"
            )


async def already_up(side: Deployment, bus: Bus) -> list[str]:
    """The services (and monitor) of this side already alive on the bus for its robot: those of
    another `beyond up`. Two sets of the same services on one robot's keys would each take the
    other's messages for their own. Alone on the bus (no peer, no router), nothing is; else
    each token is waited for ALIVE_QUERY_S at most: a peer's session learns the others' tokens
    as it meets them, after it has met the rendezvous peer (`up`'s own session)."""
    info = bus.session.info
    if not list(info.peers_zid()) and not list(info.routers_zid()):
        return []
    names = [*side.services, *([side.watcher] if side.watcher else [])]
    seen = await asyncio.gather(
        *(bus.wait_alive(bus.keys.alive(n), timeout=ALIVE_QUERY_S) for n in names),
        return_exceptions=True,
    )
    return [name for name, got in zip(names, seen, strict=True) if isinstance(got, set)]


async def watch(
    side: Deployment,
    pipeline: PipelineMonitor,
    lines: EventLines,
    timeout: float | None,
    finite: bool,
    *,
    live: bool,
) -> Ending:
    """Wait for the side to end, with the live view drawn meanwhile on a terminal; say why it
    ended unless it was asked to or done. `timeout` bounds start-up and the tail after the
    source's end (`PipelineMonitor.waited_too_long`), never a running source's silence."""
    console = Console()
    if live and console.is_terminal:
        view = lambda: render(pipeline, side.services)  # noqa: E731
        lines.live = Live(get_renderable=view, console=console, refresh_per_second=8)
        lines.live.start()
    since = time.monotonic()
    timed_out = False

    def over() -> bool:
        nonlocal timed_out
        if finite and pipeline.done():
            return True
        timed_out = timeout is not None and pipeline.waited_too_long(timeout, since)
        return timed_out

    try:
        ending = await side.wait(done=over)
        if timed_out:
            ending = Ending("timeout")
    finally:
        if lines.live is not None:
            lines.live.stop()  # drawn once more, as it ends
            lines.live = None
    if ending.reason == "exited":
        why = {n: side.restarts[n].gave_up for n in ending.exited if n in side.restarts}
        said = [f"{n} ({why[n]})" if why.get(n) else n for n in ending.exited]
        lines.emit(f"service(s) exited early: {', '.join(said)}")
    elif ending.reason == "timeout":
        lines.emit(f"timed out after {timeout:.0f} s")
    return ending


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
