"""One service process for a fleet: every robot a pattern matches, each robot's run its own.

A workstation serving ten robots used to run each service once per robot: sixty processes,
each with its own session and its own copy of the models. Here a service class runs once per
process, and what it holds per run (what `setup` builds: a tracker, a join, a watch; and what
the base keeps: the clock, the ledger, the progress, the publishers and subscriptions) is held
per robot, in a run of the class on that robot's view of the one session (`Bus.for_robot`).
Each run is exactly the single-robot service: the same keys (`beyond/<robot>/...`), its own
clock (event time per robot: one robot's replay never moves another's clock), its own ledger
and checkpoints (crash-only per robot), its own liveliness token and health, so a robot's
source and tools see the service they always saw. What costs memory and time to load (models,
a frame describer process) is loaded once per process by the services (services.shared).

A robot appears with its source: a run starts when the liveliness token of a robot's ingest
(`beyond/<robot>/alive/ingest`) matching the pattern appears, and is dropped when the token has
been gone for `leave_after_s` (30 s, or $BEYOND_ROBOT_LEAVE_S: a wall-clock wait, the machine's
business: a restarted ingest, back within seconds, keeps its robot's run, and so its state; a
robot back after that starts afresh, as a new stream of its own). The host itself is alive under
the workstation's own name (`beyond/<robot>/alive/<service>` of its config's `robot`), which
must not be one of the robots it serves.
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
from beyond_self.runtime.bus import Bus
from beyond_self.runtime.config import BusConfig
from beyond_self.runtime.log import event
from beyond_self.runtime.self_report import health_header, restarts
from beyond_self.schemas.keys import ALIVE, PREFIX, Keys, robot_matches, split_key
from beyond_self.schemas.messages import ServiceHealth

if TYPE_CHECKING:
    from beyond_self.runtime.service import Service

PRESENCE = "ingest"  # a robot is there while its source is
LEAVE_AFTER_S = 30.0
LEAVE_ENV = "BEYOND_ROBOT_LEAVE_S"  # another wait (s): a test's robots leave and come back


def leave_after_s_env() -> float:
    text = os.environ.get(LEAVE_ENV)
    try:
        value = float(text) if text else LEAVE_AFTER_S
    except ValueError:
        value = -1.0
    if not 0 <= value < float("inf"):
        raise InputError(f"{LEAVE_ENV}={text!r}; valid: a number of seconds >= 0")
    return value


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
    ) -> None:
        if config.robots is None:
            raise InputError("a fleet's service needs the robots it serves (--robots PATTERN)")
        if robot_matches(config.robots, config.robot):
            raise InputError(
                f"the workstation's own name {config.robot!r} is one of the robots it serves "
                f"({config.robots}); give it another with --robot"
            )
        self.cls = cls
        self.name: str = cls.name
        self.config = config
        self.pattern = config.robots
        self.options = dict(options or {})
        self.leave_after_s = leave_after_s if leave_after_s is not None else leave_after_s_env()
        self.runs: dict[str, Run] = {}
        self.failed: dict[str, str] = {}  # robot -> why its run ended on its own
        self._bus = bus
        self._leaving: dict[str, asyncio.TimerHandle] = {}
        self._stop = asyncio.Event()
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
        try:
            bus.watch_tokens(f"{PREFIX}/{self.pattern}/{ALIVE}/{PRESENCE}", self._presence)
            own = Keys(self.config.robot)

            async def answer_health(_key: str, _request: None) -> ServiceHealth:
                return self.health_report()

            bus.queryable(own.health(self.name), None, answer_health)
            bus.declare_token(own.alive(self.name))
            event(self.log, logging.INFO, "serving robots", service=self.name, robots=self.pattern)
            await self._stop.wait()
        finally:
            for handle in self._leaving.values():
                handle.cancel()
            await asyncio.gather(*(self._drop(robot) for robot in list(self.runs)))
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
        )

    def _presence(self, key: str, present: bool) -> None:
        split = split_key(key)
        if split is None or self._stop.is_set():
            return
        robot = split[0]
        if present:
            pending = self._leaving.pop(robot, None)
            if pending is not None:
                pending.cancel()
            if robot not in self.runs:
                self._start(robot)
        elif robot in self.runs and robot not in self._leaving:
            loop = asyncio.get_running_loop()
            self._leaving[robot] = loop.call_later(self.leave_after_s, self._left, robot)

    def _left(self, robot: str) -> None:
        self._leaving.pop(robot, None)
        event(self.log, logging.INFO, "robot left", service=self.name, robot=robot)
        asyncio.get_running_loop().create_task(self._drop(robot))

    def _start(self, robot: str) -> None:
        bus = self._host_bus().for_robot(robot)
        config = self.config.with_(robot=robot, robots=None)
        service = self.cls(config=config, bus=bus, **self.options)
        task = asyncio.get_running_loop().create_task(
            service.run(install_signals=False), name=f"{self.name}: {robot}"
        )
        self.runs[robot] = Run(service, task, bus)
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
                run.bus.close()

        return ended

    async def _drop(self, robot: str) -> None:
        run = self.runs.pop(robot, None)
        if run is None:
            return
        run.service.stop()
        await asyncio.gather(run.task, return_exceptions=True)
        run.bus.close()

    def _host_bus(self) -> Bus:
        if self._bus is None:
            raise RuntimeError("the bus is open only while the fleet runs")
        return self._bus
