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
been gone for `leave_after_s` (a wall-clock wait, the machine's business: a restarted ingest,
back within seconds, keeps its robot's run, and so its state). The host itself is alive under
the workstation's own name (`beyond/<robot>/alive/<service>` of its config's `robot`), which
must not be one of the robots it serves.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from beyond_self.core.errors import InputError
from beyond_self.runtime import process
from beyond_self.runtime.bus import Bus
from beyond_self.runtime.config import BusConfig
from beyond_self.runtime.log import event
from beyond_self.schemas.keys import ALIVE, PREFIX, Keys, robot_matches, split_key

if TYPE_CHECKING:
    from beyond_self.runtime.service import Service

PRESENCE = "ingest"  # a robot is there while its source is
LEAVE_AFTER_S = 30.0


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
        leave_after_s: float = LEAVE_AFTER_S,
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
        self.leave_after_s = leave_after_s
        self.runs: dict[str, Run] = {}
        self.failed: dict[str, str] = {}  # robot -> why its run ended on its own
        self._bus = bus
        self._leaving: dict[str, asyncio.TimerHandle] = {}
        self._stop = asyncio.Event()
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
            bus.declare_token(Keys(self.config.robot).alive(self.name))
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
