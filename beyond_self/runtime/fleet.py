"""One service process for a fleet: every robot a pattern matches, each robot's run its own.

One process per service, not one per robot, so the models load once per process (services.shared).
What a run holds (what `setup` builds; the base's clock, ledger, progress, publishers) is per
robot, on that robot's view of the one session (`Bus.for_robot`): each run is exactly the
single-robot service, on its keys, with its own event time, checkpoints, token and health.
A run starts when the robot's ingest token appears (a robot its `shard` gives it, if any) and ends
`leave_after_s` after it has gone. One host serves a robot at a time (`Keys.server`); a standby
takes a robot over after `takeover_after_s`, sink first, so each new run finds its consumers' new
instances and sends them what they need to rebuild. Failover, waits: docs/concepts/fleets.md.
"""

from __future__ import annotations

import asyncio
import logging
import os
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from beyond_self.core.errors import InputError
from beyond_self.runtime import process
from beyond_self.runtime.bus.config import BusConfig
from beyond_self.runtime.bus.demux import SharedStreams
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.log import event
from beyond_self.runtime.self_report import health_header, restarts
from beyond_self.runtime.shard import Shard
from beyond_self.schemas.keys import Keys, for_robots, robot_matches, split_key
from beyond_self.schemas.messages import ServiceHealth

if TYPE_CHECKING:
    from beyond_self.runtime.service import Service

PRESENCE = "ingest"  # a robot is there while its source is
LEAVE_AFTER_S = 30.0
LEAVE_ENV = "BEYOND_ROBOT_LEAVE_S"  # another wait (s): a test's robots leave and come back
# a standby waits this long with a robot unserved before it serves it: longer than a host's own
# runs take to declare their tokens, so a standby never races a workstation starting up
TAKEOVER_AFTER_S = 3.0
TAKEOVER_ENV = "BEYOND_TAKEOVER_S"
# at most this much longer per stage after it in the pipeline, for consumers that do not come
# back: a stage goes as soon as its consumers' new runs are there
TAKEOVER_STEP_S = 1.5


def takeover_latest_s(stages_after: int) -> float:
    """The longest a standby waits for a service with `stages_after` services after it."""
    return seconds_env(TAKEOVER_ENV, TAKEOVER_AFTER_S) + TAKEOVER_STEP_S * stages_after


def seconds_env(name: str, default: float) -> float:
    """A wall-clock wait from the environment (the machine's business, never an output's)."""
    text = os.environ.get(name)
    try:
        value = float(text) if text else default
    except ValueError:
        value = -1.0
    if not 0 <= value < float("inf"):
        raise InputError(f"{name}={text!r}; valid: a number of seconds >= 0")
    return value


def leave_after_s_env() -> float:
    return seconds_env(LEAVE_ENV, LEAVE_AFTER_S)


@dataclass
class Run:
    """One robot's run of the service: the instance, its task, its view of the session."""

    service: Service
    task: asyncio.Task[None]
    bus: Bus


class Fleet:
    """Service class `cls` (options `options`) for every robot `config.robots` matches."""

    def __init__(
        self,
        cls: type[Service],
        config: BusConfig,
        options: Mapping[str, Any] | None = None,
        *,
        bus: Bus | None = None,
        leave_after_s: float | None = None,
        takeover_after_s: float | None = None,
        consumers: tuple[str, ...] = (),
        takeover_latest_s: float | None = None,
        shard: Shard | None = None,
    ) -> None:
        if config.robots is None:
            raise InputError("a fleet's service needs the robots it serves (--robots PATTERN)")
        for pattern in (config.robots, config.standby):
            if pattern is not None and robot_matches(pattern, config.robot):
                raise InputError(
                    f"the workstation's own name {config.robot!r} is one of the robots it "
                    f"serves ({pattern}); give it another with --robot"
                )
        self.cls = cls
        self.name: str = cls.name
        self.config = config
        self.pattern = config.robots
        self.standby = config.standby
        self.shard = shard  # None: every robot the patterns match
        self.host = config.robot  # the workstation's own name: its runs' server tokens say it
        self.options = dict(options or {})
        self.leave_after_s = leave_after_s if leave_after_s is not None else leave_after_s_env()
        self.takeover_after_s = (
            takeover_after_s
            if takeover_after_s is not None
            else seconds_env(TAKEOVER_ENV, TAKEOVER_AFTER_S)
        )
        self.consumers = consumers
        self.takeover_latest_s = max(self.takeover_after_s, takeover_latest_s or 0.0)
        self.runs: dict[str, Run] = {}
        self.failed: dict[str, str] = {}  # robot -> why its run ended on its own
        self.present: set[str] = set()  # robots whose source is there
        self.served_by: dict[str, set[str]] = {}  # robot -> the other hosts serving it
        self.takeovers = 0  # robots this host began serving after no other host did
        self.consumers_seen: dict[str, set[str]] = {}  # robot -> consumers ever seen serving it
        self.consumers_alive: dict[str, set[str]] = {}  # robot -> consumers with a run for it now
        self._bus = bus
        self._leaving: dict[str, asyncio.TimerHandle] = {}
        self._takeover: dict[str, asyncio.TimerHandle] = {}  # robot -> its wait's end
        self._latest: dict[str, asyncio.TimerHandle] = {}  # robot -> the wait on consumers' end
        self._unserved_since: dict[str, float] = {}  # robot -> when its takeover wait began
        self._server_tokens: dict[str, Callable[[], None]] = {}
        self._stop = asyncio.Event()
        self._shared: SharedStreams | None = None  # the primary robots' streams, while running
        self._health_seq = 0
        self.started_at = time.monotonic()
        self.log = logging.getLogger(f"beyond.{self.name}")

    @property
    def robots(self) -> list[str]:
        return sorted(self.runs)

    def stop(self) -> None:
        self._stop.set()

    async def run(self, *, install_signals: bool = True) -> None:
        """Serve every robot that comes, until stopped; then stop each robot's run cleanly."""
        owns = self._bus is None
        if self._bus is None:
            self._bus = Bus.open(self.config)
        bus = self._bus
        installed = process.install_signals(self.stop) if install_signals else []
        assert self.pattern is not None  # checked at construction
        # A secure robot's router lets through declarations on its own robot's keys only: a
        # subscriber on the whole pattern would never be matched there
        if self.config.secure is None:
            self._shared = SharedStreams(bus.session, self.pattern, self._keeps)
        try:
            for pattern in self._patterns:
                keys = Keys()  # any robot's: for_robots puts the pattern in its place
                bus.watch_tokens(for_robots(pattern, keys.alive(PRESENCE)), self._presence)
                bus.watch_tokens(for_robots(pattern, keys.server(self.name)), self._server)
                for consumer in self.consumers:
                    bus.watch_tokens(for_robots(pattern, keys.alive(consumer)), self._consumer)
            own = Keys(self.config.robot)

            async def answer_health(_key: str, _request: None) -> ServiceHealth:
                return self.health_report()

            bus.queryable(own.health(self.name), None, answer_health)
            bus.declare_token(own.alive(self.name))
            event(self.log, logging.INFO, "serving robots", service=self.name, robots=self.pattern,
                  shard=str(self.shard or "-"))  # fmt: skip
            await self._stop.wait()
        finally:
            timers = [*self._leaving.values(), *self._takeover.values(), *self._latest.values()]
            for handle in timers:
                handle.cancel()
            await asyncio.gather(*(self._drop(robot) for robot in list(self.runs)))
            if self._shared is not None:
                self._shared.close()
                self._shared = None
            for sig in installed:
                asyncio.get_running_loop().remove_signal_handler(sig)
            if owns:
                bus.close()
                self._bus = None

    def health_report(self) -> ServiceHealth:
        """The process's health, for its supervisor (`beyond up`'s health watch): every
        robot's run summed; a robot's own is its run's, on its keys."""
        runs = [r.service.health_report() for r in self.runs.values() if r.service.started.is_set()]
        seq, self._health_seq = self._health_seq, self._health_seq + 1
        last_error = next((h.last_error for h in runs if h.last_error), "")
        return ServiceHealth(
            header=health_header(self.name, seq, max((h.header.stamp for h in runs), default=0)),
            service=self.name,
            uptime_s=round(time.monotonic() - self.started_at, 3),
            messages_in=sum(h.messages_in for h in runs),
            messages_out=sum(h.messages_out for h in runs),
            dropped=sum(h.dropped for h in runs),
            malformed=sum(h.malformed for h in runs),
            errors=sum(h.errors for h in runs) + len(self.failed),
            last_error=last_error or next(iter(self.failed.values()), ""),
            skipped=sum(h.skipped for h in runs),
            restarts=restarts(),
            stale=sum(h.stale for h in runs),
            foreign=sum(h.foreign for h in runs),
            refused=sum(h.refused for h in runs),
        )

    @property
    def _patterns(self) -> list[str]:
        assert self.pattern is not None  # checked at construction
        return [self.pattern] + ([self.standby] if self.standby is not None else [])

    def _primary(self, robot: str) -> bool:
        return self.pattern is not None and robot_matches(self.pattern, robot)

    def _keeps(self, robot: str) -> bool:
        """Whether the shared streams keep a robot's samples until its run subscribes: a robot
        this process serves first-hand (a standby's robots have runs of their own streams)."""
        mine = self.shard is None or self.shard.serves(robot)
        return mine and self._primary(robot) and not self.served_by.get(robot)

    def _presence(self, key: str, present: bool) -> None:
        split = split_key(key)
        if split is None or self._stop.is_set():
            return
        robot = split[0]
        if self.shard is not None and not self.shard.serves(robot):
            return  # a sibling shard's, never this process's: not even as a standby
        if present:
            self.present.add(robot)
            pending = self._leaving.pop(robot, None)
            if pending is not None:
                pending.cancel()
            self._review(robot)
        else:
            self.present.discard(robot)
            self._review(robot)
            if robot in self.runs and robot not in self._leaving:
                loop = asyncio.get_running_loop()
                self._leaving[robot] = loop.call_later(self.leave_after_s, self._left, robot)

    def _server(self, key: str, present: bool) -> None:
        """Another host's run began or stopped serving a robot's service."""
        split = split_key(key)
        if split is None or self._stop.is_set():
            return
        robot, host = split[0], key.rsplit("/", 1)[1]
        if host == self.host:
            return  # this host's own runs
        hosts = self.served_by.setdefault(robot, set())
        (hosts.add if present else hosts.discard)(host)
        self._review(robot)

    def _consumer(self, key: str, present: bool) -> None:
        """A consumer's run for a robot began or ended (any host's)."""
        split = split_key(key)
        if split is None or self._stop.is_set():
            return
        robot, consumer = split[0], key.rsplit("/", 1)[1]
        alive = self.consumers_alive.setdefault(robot, set())
        if present:
            alive.add(consumer)
            self.consumers_seen.setdefault(robot, set()).add(consumer)
            if robot in self._unserved_since and robot not in self._takeover:
                self._take(robot)  # past its wait, waiting on its consumers
        else:
            alive.discard(consumer)

    def _review(self, robot: str) -> None:
        """Serve `robot` if it is there and no other host does; yield it to a host whose
        name sorts first if both do."""
        others = self.served_by.get(robot, set())
        if robot in self.runs:
            if any(host < self.host for host in others):
                event(self.log, logging.INFO, "robot served elsewhere: yielding",
                      service=self.name, robot=robot, to=min(others))  # fmt: skip
                asyncio.get_running_loop().create_task(self._drop(robot))
            return
        if robot not in self.present or others:
            self._no_takeover(robot)
            return
        if self._primary(robot):
            self._start(robot)
        elif robot not in self._unserved_since:
            loop = asyncio.get_running_loop()
            self._unserved_since[robot] = loop.time()
            self._takeover[robot] = loop.call_later(self.takeover_after_s, self._take, robot)

    def _no_takeover(self, robot: str) -> None:
        for timers in (self._takeover, self._latest):
            pending = timers.pop(robot, None)
            if pending is not None:
                pending.cancel()
        self._unserved_since.pop(robot, None)

    def _take(self, robot: str, anyway: bool = False) -> None:
        """A standby's wait is over: serve the robot if it is still there and served by no
        host, once the consumers seen serving it have runs for it again (`anyway`: the latest
        wait is over, they are not waited for any more)."""
        self._takeover.pop(robot, None)
        since = self._unserved_since.get(robot)
        if since is None:
            return
        if robot not in self.present or self.served_by.get(robot) or robot in self.runs:
            self._no_takeover(robot)
            return
        loop = asyncio.get_running_loop()
        waited = loop.time() - since
        missing = self.consumers_seen.get(robot, set()) - self.consumers_alive.get(robot, set())
        if missing and not anyway:
            if robot not in self._latest:  # a consumer's new run comes, or this ends
                latest = max(self.takeover_latest_s - waited, 0.0)
                self._latest[robot] = loop.call_later(latest, self._take, robot, True)
            return
        self._no_takeover(robot)
        self.takeovers += 1
        event(self.log, logging.WARNING, "serving a robot no host serves",
              service=self.name, robot=robot, waited_s=round(waited, 3),
              consumers_missing=sorted(missing))  # fmt: skip
        self._start(robot)

    def _left(self, robot: str) -> None:
        self._leaving.pop(robot, None)
        event(self.log, logging.INFO, "robot left", service=self.name, robot=robot)
        asyncio.get_running_loop().create_task(self._drop(robot))

    def _start(self, robot: str) -> None:
        bus = self._host_bus().for_robot(robot, self._shared if self._keeps(robot) else None)
        config = self.config.with_(robot=robot, robots=None, standby=None)
        service = self.cls(config=config, bus=bus, **self.options)
        service._fleet_member = True
        task = asyncio.get_running_loop().create_task(
            service.run(install_signals=False), name=f"{self.name}: {robot}"
        )
        self.runs[robot] = Run(service, task, bus)
        self._server_tokens[robot] = self._host_bus().declare_token(
            Keys(robot).server(self.name, self.host)
        )
        task.add_done_callback(self._ended(robot))
        event(self.log, logging.INFO, "robot joined", service=self.name, robot=robot)

    def _ended(self, robot: str) -> Callable[[asyncio.Task[None]], None]:
        def ended(task: asyncio.Task[None]) -> None:
            if task.cancelled() or task.exception() is None:
                return
            why = str(task.exception())
            self.failed[robot] = why
            self.log.error("robot %s: %s", robot, why)  # that robot's run only; others go on
            run = self.runs.pop(robot, None)
            if run is not None:
                self._no_longer_serving(robot)
                run.bus.close()

        return ended

    async def _drop(self, robot: str) -> None:
        run = self.runs.pop(robot, None)
        if run is None:
            return
        run.service.stop()
        await asyncio.gather(run.task, return_exceptions=True)
        self._no_longer_serving(robot)
        run.bus.close()

    def _no_longer_serving(self, robot: str) -> None:
        if self._shared is not None:
            self._shared.forget(robot)
        undeclare = self._server_tokens.pop(robot, None)
        if undeclare is not None:
            undeclare()

    def _host_bus(self) -> Bus:
        if self._bus is None:
            raise RuntimeError("the bus is open only while the fleet runs")
        return self._bus
