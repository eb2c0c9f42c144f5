"""A set of services run as processes on one bus: what `beyond up`, and every test and benchmark
that runs several services, starts, watches and stops, so a pipeline is run one way.

    deployment = Deployment(config, ["gestures", "reasoner"], options={"reasoner": {...}})
    bus = await deployment.open()  # optional: subscribe here to see the services' first output
    await deployment.start()  # every process alive on the bus, or exited; the source last
    ending = await deployment.wait(timeout=60, done=lambda: ...)  # why it returned
    codes = await deployment.stop()  # each process's exit code

A service that dies is started again (services.supervision); what to print is the caller's.
"""

from __future__ import annotations

import asyncio
import contextlib
import signal
from collections.abc import Awaitable, Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

from beyond_self.core.errors import InputError, unknown
from beyond_self.runtime import process
from beyond_self.runtime.bus.config import BusConfig
from beyond_self.runtime.self_report import RESTARTS_ENV
from beyond_self.services.launcher import (
    HealthWatch,
    LogSink,
    ServiceProcess,
    kill_group,
    release,
    service_env,
    start_service,
    stop_services,
)
from beyond_self.services.link_watch import SILENT_S, LinkWatch
from beyond_self.services.options import check_options
from beyond_self.services.registry import PIPELINE, service_class
from beyond_self.services.supervision import RestartPolicy, Restarts, how_it_ended
from beyond_self.services.units import plan_units

if TYPE_CHECKING:
    from beyond_self.runtime.bus.session import Bus

SOURCE = "ingest"  # the service that publishes sensor streams, started last
ROUTER = "router"  # a secure side's own router, supervised like a service
ALIVE_TIMEOUT_S = 60.0  # a process neither alive nor exited after this long: start() fails
POLL_S = 0.25  # how often wait() looks at the processes and the caller's `done`
CLOCKS = ("wall", "recording")
DEFAULT_RESTART = RestartPolicy()


@dataclass(frozen=True)
class Ending:
    """Why `Deployment.wait` returned: `done` (the caller's condition), `stopped` (a signal or
    `request_stop`), `exited` (these processes ended on their own) or `timeout`."""

    reason: Literal["done", "stopped", "exited", "timeout"]
    exited: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        return self.reason in ("done", "stopped")


class Deployment:
    """The services `services` (names of `services.registry`) on the bus `config`.

    `options` are each service's keyword options, checked here, before anything starts. The
    source, if there is one, waits for every other service of the deployment, for `watcher`
    (the liveliness name this process declares once it watches) and for `wait_for` (services
    elsewhere). `clock="recording"`: the services follow the source's stamps (a replay).
    `router`: arguments of `beyond router` for a secure side's own router, started first and
    stopped last. `env`: extra environment of the services (log format, level). `log` receives
    every line a process prints. With `on_stuck`, a health watch asks every process for its
    health and reports there, then stops, one that no longer answers (without it nothing is
    stopped behind the caller's back: a benchmark on a loaded machine is slow, not stuck).
    `stop_on_signals`: SIGINT/SIGTERM end `wait` (as Ctrl-C ends `beyond up`). `restart`: a
    service that dies is started again as the policy says (services.supervision; None: never),
    and `on_restart(name, what)` is told each restart and each time the policy gives up. With a
    restart policy the router is supervised too, and restarted when the other side is present
    but none of its health has arrived for `link_silent_s` (services.link_watch). `shards` N > 1:
    a fleet's services run as N shards each, each process its own (`units`: services.units)."""

    def __init__(
        self,
        config: BusConfig,
        services: Sequence[str],
        *,
        options: Mapping[str, Mapping[str, Any]] | None = None,
        wait_for: Sequence[str] = (),
        watcher: str | None = None,
        clock: str = "wall",
        router: Sequence[str] | None = None,
        env: Mapping[str, str] | None = None,
        log: LogSink | None = None,
        on_stuck: Callable[[str, str], None] | None = None,
        stop_on_signals: bool = False,
        restart: RestartPolicy | None = DEFAULT_RESTART,
        on_restart: Callable[[str, str], None] | None = None,
        link_silent_s: float = SILENT_S,
        shards: int = 1,
    ) -> None:
        if clock not in CLOCKS:
            raise unknown("clock", clock, CLOCKS)
        self.config = config
        self.services = list(services)
        self.options = _checked_options(self.services, options or {})
        fleet = [n for n in self.services if service_class(n).fleet]
        self.units = plan_units(config, self.services, shards, fleet)  # its processes, by name
        if SOURCE in self.services:
            local = [n for n in self.services if n != SOURCE] + ([watcher] if watcher else [])
            self.options[SOURCE]["wait_for"] = local + list(wait_for)
        self.watcher = watcher
        self.router_command = list(router) if router is not None else None
        self.clock = clock  # its services' (and its watcher's: beyond_self.monitor)
        clock_env = {"BEYOND_CLOCK": "recording"} if clock == "recording" else {}
        self.env = service_env(config, {**(env or {}), **clock_env})
        self.log = log
        self.on_stuck = on_stuck
        self.stop_on_signals = stop_on_signals
        self.bus: Bus | None = None
        self.router: ServiceProcess | None = None
        self.processes: list[ServiceProcess] = []  # the services' current processes
        self.health_watch: HealthWatch | None = None
        self.link_watch: LinkWatch | None = None
        self.codes: dict[str, int] = {}  # exit codes, once stopped
        self._stopping = asyncio.Event()
        self._token: Callable[[], None] | None = None
        self._closers: list[Callable[[], Awaitable[object]]] = []
        self._signals: list[signal.Signals] = []
        self.restart = restart
        self.on_restart = on_restart
        self.link_silent_s = link_silent_s
        self.restarts: dict[str, Restarts] = {}  # per service, once it has died
        self._judged: dict[str, ServiceProcess] = {}  # the last dead process of each, decided
        self._final: set[str] = set()  # ended for good: not restarted
        self._pending: dict[str, asyncio.Task[None]] = {}  # restarts waiting out their delay
        self._supervisor: asyncio.Task[None] | None = None
        self._closing = asyncio.Event()

    # -- starting --------------------------------------------------------------------------

    async def open(self) -> Bus:
        """This process's session (after the router, if any): call it before `start` to
        subscribe before the services publish. Idempotent."""
        if self.bus is not None:
            return self.bus
        if self.stop_on_signals:
            # services run in their own sessions, so Ctrl-C reaches only us: we stop them in order
            self._signals = process.install_signals(self._stopping.set)
        if self.router_command is not None:
            await self._launch_router()
        from beyond_self.runtime.bus.session import (
            Bus,  # here: zenoh is slow to import, building a plan needs none
        )

        try:
            self.bus = Bus.open(self.config)  # a secure client waits here for its router
        except BaseException:
            if self._supervisor is not None:  # it would start the router again
                self._supervisor.cancel()
                self._supervisor = None
            await self._stop_router()
            raise
        return self.bus

    async def prepare(self) -> None:
        """Start the process of every service not started yet, held: it imports what it runs,
        most of its start, then waits off the bus until `start` (or `launch`) lets it join.
        Whatever the caller does meanwhile (open the session, look for another deployment on
        the bus) overlaps the processes' own start; `stop` ends those never let in."""
        for name in self.units:
            if all(sp.name != name for sp in self.processes):
                await self._spawn(name, held=True)

    async def start(self) -> None:
        """Start every service, the source last, and return once each is alive on the bus (its
        health then answers) or has exited (`wait` reports it); TimeoutError if one is
        neither after ALIVE_TIMEOUT_S. Every process is started first, held (`prepare`), so
        the source's interpreter starts beside the others', and joins the bus after them.

        The source starts only once the others are alive, each awaited once: its session then
        meets theirs already meshed, and Zenoh routes what it publishes to them directly. Started
        together, a robot's source can learn its consumers through the workstation's router
        first and keep sending them its frames by that detour, and a cut link would then stall
        the robot's own pipeline until Zenoh gives the link up (tests/test_deploy_netns.py)."""
        await self.prepare()
        bus = await self.open()
        units = self.units.values()
        for group in ([u.name for u in units if u.service != SOURCE], [SOURCE]):
            launched = [await self.launch(name) for name in group if name in self.units]
            await asyncio.gather(*(_alive_or_exited(bus, sp, ALIVE_TIMEOUT_S) for sp in launched))
        if self.on_stuck is not None:
            self.health_watch = HealthWatch(bus, self.processes, self.on_stuck)
            self.health_watch.start()
        if self.router is not None and self.restart is not None:
            remote = [name for name in PIPELINE if name not in self.services]
            self.link_watch = LinkWatch(
                bus, remote, self.restart_router, silent_s=self.link_silent_s
            )
            self.link_watch.start()

    async def launch(self, name: str) -> ServiceProcess:
        """Start service `name` of this deployment, or start it again after it exited: the new
        process takes the old one's place in `processes` (and in the health watch); one
        started held (`prepare`) is let in. `start` launches them all; launch them one by one
        instead to choose the order (tests)."""
        if name not in self.units:
            raise unknown("service of this deployment", name, list(self.units))
        bus = await self.open()
        if self.watcher is not None and self._token is None:
            # after the caller's subscriptions, before any service: the source waits for it
            self._token = bus.declare_token(bus.keys.alive(self.watcher))
        held = next((sp for sp in self.processes if sp.name == name and sp.held), None)
        if held is not None:
            release(held)
            return held
        return await self._spawn(name)

    async def _spawn(self, name: str, *, held: bool = False) -> ServiceProcess:
        old = next((i for i, sp in enumerate(self.processes) if sp.name == name), None)
        if old is not None and self.processes[old].running:
            raise InputError(f"service {name} is already running in this deployment")
        restarts = self.restarts.get(name)
        env = self.env if restarts is None else {**self.env, RESTARTS_ENV: str(restarts.count)}
        unit = self.units[name]
        sp = await start_service(
            name, env, options=self.options[unit.service], sink=self.log, held=held,
            command=unit.command, service=unit.service, robot=unit.robot,
        )  # fmt: skip
        if old is None:
            self.processes.append(sp)
        else:
            self.processes[old] = sp
        self._final.discard(name)
        if self.health_watch is not None:
            self.health_watch.misses.pop(name, None)  # a new process: its own record
        self._supervised()
        return sp

    def _supervised(self) -> None:
        """The supervisor runs from the first process started (the router, or a service)."""
        if self.restart is not None and self._supervisor is None:
            self._supervisor = asyncio.get_running_loop().create_task(self._supervise())

    async def _launch_router(self) -> None:
        assert self.router_command is not None
        command, env = self.router_command, self._router_env()
        self.router = await start_service(ROUTER, env, command=command, sink=self.log)
        self._final.discard(ROUTER)
        self._supervised()

    def restart_router(self, why: str) -> None:
        """Kill this side's router (SIGKILL: a router wedged on a dead link may never finish a
        clean close) for the supervisor to start again, and say why."""
        if self.router is None or not self.router.running or self._closing.is_set():
            return
        self._tell(ROUTER, f"{why}; killing it to start it again")
        with contextlib.suppress(ProcessLookupError):
            self.router.process.kill()

    def attach(self, close: Callable[[], Awaitable[object]]) -> None:
        """`close` runs in `stop`, once the services have stopped and before the router and the
        session: for what rides on this deployment's session (a Foxglove bridge)."""
        self._closers.append(close)

    # -- watching --------------------------------------------------------------------------

    def exited(self) -> list[str]:
        """Names of the processes (router included) that are no longer running and will not be
        started again (the restart policy gave up on them, or they stopped as they meant to)."""
        router = [self.router] if self.router is not None and not self.router.running else []
        if self.restart is None:
            return [sp.name for sp in self.processes + router if not sp.running]
        return [n for n in [ROUTER, *self.units] if n in self._final]

    async def _supervise(self) -> None:
        """Start again, as the restart policy says, every service that dies, and the router."""
        assert self.restart is not None
        loop = asyncio.get_running_loop()
        while True:
            router = [self.router] if self.router is not None else []
            for sp in [*router, *self.processes]:
                if sp.running or self._judged.get(sp.name) is sp or sp.name in self._pending:
                    continue
                if sp.held:  # it died before it was let in: judged once it is (`start`)
                    continue
                self._judged[sp.name] = sp
                kill_group(sp)  # what it started (a synthesizer) dies with it
                code = sp.process.returncode
                assert code is not None
                restarts = self.restarts.setdefault(sp.name, Restarts(self.restart))
                delay = restarts.decide(code, sp.stuck, loop.time())
                if delay is None:
                    self._final.add(sp.name)
                    if restarts.gave_up:
                        self._tell(sp.name, restarts.gave_up)
                    continue
                why = "stuck" if sp.stuck else how_it_ended(code)
                self._tell(sp.name, f"{why}; restart {restarts.count} in {delay:g} s")
                self._pending[sp.name] = loop.create_task(self._restart(sp.name, delay))
            await asyncio.sleep(POLL_S / 2)

    async def _restart(self, name: str, delay: float) -> None:
        """Start `name` again after `delay`, unless the deployment stops meanwhile. Never
        cancelled while it launches: a process spawned but not yet in `processes` would be
        left running when everything stops."""
        try:
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(delay):
                    await self._closing.wait()
            if not self._closing.is_set():
                if name == ROUTER:
                    await self._launch_router()
                else:
                    await self.launch(name)
        finally:
            self._pending.pop(name, None)

    def _tell(self, name: str, what: str) -> None:
        if self.on_restart is not None:
            self.on_restart(name, what)

    def request_stop(self) -> None:
        """End `wait` as a signal would."""
        self._stopping.set()

    async def wait(
        self, timeout: float | None = None, *, done: Callable[[], bool] | None = None
    ) -> Ending:
        """Until `done()` holds, a process exits, `timeout` s pass or a stop is requested (a
        signal, with `stop_on_signals`). A stop requested first wins: Ctrl-C is never reported
        as a failure."""
        loop = asyncio.get_running_loop()
        deadline = None if timeout is None else loop.time() + timeout
        while not self._stopping.is_set():
            if done is not None and done():
                return Ending("done")
            if exited := self.exited():
                return Ending("exited", tuple(exited))
            if deadline is not None and loop.time() > deadline:
                return Ending("timeout")
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._stopping.wait(), POLL_S)
        return Ending("stopped")

    # -- stopping --------------------------------------------------------------------------

    async def stop(self) -> dict[str, int]:
        """Stop everything cleanly, in reverse order of start: the health watch, the watcher's
        token, the services (SIGTERM, then SIGKILL if hung), what was attached, the router last,
        then the session. Returns (and keeps in `codes`) every process's exit code."""
        try:
            self._closing.set()  # nothing is started again while everything stops
            if self._supervisor is not None:
                self._supervisor.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await self._supervisor
                self._supervisor = None
            await asyncio.gather(*self._pending.values(), return_exceptions=True)
            if self.health_watch is not None:
                await self.health_watch.stop()
            if self.link_watch is not None:
                await self.link_watch.stop()
            if self._token is not None:
                self._token()
                self._token = None
            self.codes = await stop_services(self.processes)
            for close in self._closers:
                await close()
            self._closers.clear()
            self.codes.update(await self._stop_router())
        finally:
            if self.bus is not None:
                self.bus.close()
                self.bus = None
            loop = asyncio.get_running_loop()
            for sig in self._signals:
                loop.remove_signal_handler(sig)
            self._signals = []
        return self.codes

    def unclean(self) -> dict[str, int]:
        """The processes that did not stop cleanly. Killed by our SIGTERM counts as clean: a
        process still starting has no handler of its own yet."""
        return {n: c for n, c in self.codes.items() if c not in (0, -signal.SIGTERM)}

    async def _stop_router(self) -> dict[str, int]:
        router, self.router = self.router, None
        return await stop_services([router]) if router is not None else {}

    def _router_env(self) -> dict[str, str]:
        """A secure side's router: secure defaults and its own endpoints, not the clients'."""
        own = BusConfig(
            robot=self.config.robot,
            mode="router",
            secure=self.config.secure,
            port=self.config.port,
        )
        return service_env(own)


def _checked_options(
    names: list[str], options: Mapping[str, Mapping[str, Any]]
) -> dict[str, dict[str, Any]]:
    """Each service's options, refused (one line) before anything starts if a service or an
    option is unknown: a typo found after the others have started would leave them running."""
    checked = {name: dict(options.get(name, {})) for name in names}
    for name in names:
        check_options(name, service_class(name), checked[name])
    return checked


async def _alive_or_exited(bus: Bus, sp: ServiceProcess, timeout: float) -> None:
    """Until `sp`'s liveliness token is seen (declared after its health queryable, so it then
    answers health) or it exited (`wait` then reports it): a process merely spawned serves
    nothing yet, and whoever takes "pipeline up" at its word asks the services for their health."""
    alive = asyncio.ensure_future(bus.wait_alive(sp.alive_key(bus.keys), timeout=timeout))
    exited = asyncio.ensure_future(sp.process.wait())
    try:
        await asyncio.wait({alive, exited}, return_when=asyncio.FIRST_COMPLETED)
    finally:
        alive.cancel()
        exited.cancel()
    if alive.done() and not alive.cancelled():
        error = alive.exception()  # no token in time: a TimeoutError
        if error is not None and not (exited.done() and not exited.cancelled()):
            raise error
