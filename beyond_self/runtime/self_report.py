"""What a service says about itself: its health (answered and published every second) and the
counts it logs when it stops. Kept apart from runtime.service, which runs the service: what is
read of a service here is `Reporting`, which the Service base is, so neither imports the other."""

from __future__ import annotations

import logging
import os
import time
from typing import TYPE_CHECKING, Any, Protocol

from beyond_self.runtime.log import event
from beyond_self.schemas.base import Header
from beyond_self.schemas.messages import ServiceHealth

if TYPE_CHECKING:
    from beyond_self.runtime.bus.publisher import Publisher
    from beyond_self.runtime.bus.session import Bus
    from beyond_self.runtime.bus.subscription import Subscription
    from beyond_self.runtime.clock import Clock
    from beyond_self.runtime.error_account import ErrorAccount
    from beyond_self.runtime.event_time import SourceTimes
    from beyond_self.runtime.progress import ProgressReport

RESTARTS_ENV = "BEYOND_RESTARTS"  # set by a supervisor (services.supervision) on a restart
_STOP_COUNTS = ("messages_in", "messages_out", "malformed", "dropped", "errors", "restarts")


class Duplicates(Protocol):
    """Where a service counts the messages it skipped as handled already (its ledgers)."""

    @property
    def duplicates(self) -> int: ...


class Reporting(Protocol):
    """What a report reads of a running service (runtime.service.Service): its public face and
    the runtime's own bookkeeping of it, which a service author never touches."""

    @property
    def name(self) -> str: ...
    @property
    def bus(self) -> Bus: ...
    @property
    def clock(self) -> Clock: ...
    @property
    def log(self) -> logging.Logger: ...

    @property
    def _started_at(self) -> float: ...
    @property
    def _subscriptions(self) -> list[tuple[Subscription[Any], Any]]: ...
    @property
    def _publishers(self) -> list[Publisher[Any]]: ...
    @property
    def _progress(self) -> ProgressReport: ...
    @property
    def _account(self) -> ErrorAccount: ...
    @property
    def _times(self) -> SourceTimes: ...
    @property
    def _ledgers(self) -> Duplicates: ...


def restarts() -> int:
    """How many times this service was restarted before this instance (its supervisor says)."""
    text = os.environ.get(RESTARTS_ENV, "0")
    return int(text) if text.isdigit() else 0


def health_header(name: str, seq: int, stamp: int) -> Header:
    """The header of service `name`'s `seq`-th health report, stamped `stamp`."""
    return ServiceHealth.original_header(name, seq, stamp, chain="health")


def health_of(service: Reporting, seq: int) -> ServiceHealth:
    subs, publishers = [s for s, _ in service._subscriptions], service._publishers
    keys = service.bus.keys
    return ServiceHealth(
        header=health_header(service.name, seq, service.clock.now_ns()),
        service=service.name,
        uptime_s=round(time.monotonic() - service._started_at, 3),
        messages_in=sum(s.received for s in subs),
        messages_out=sum(p.sent for p in publishers),
        dropped=sum(s.dropped for s in subs),
        malformed=sum(s.malformed for s in subs) + service._account.malformed_other,
        errors=service._account.errors,
        last_error=service._account.last_error,
        inputs=sorted({s.key for s in subs}),
        outputs=sorted(
            {p.key for p in publishers}
            | ({keys.progress(service.name)} if service._progress.paced else set())
        ),
        restarts=restarts(),
        stale=service._times.stale,
        foreign=service._times.foreign,
        refused=service._times.refused,
    )


def stop_counts(service: Reporting, health: ServiceHealth) -> dict[str, Any]:
    """What a stopping service logs: its counts, what caches gave back, what it skipped."""
    recovered, missed = recovery_of([s for s, _ in service._subscriptions])
    counts: dict[str, Any] = {"service": service.name}
    counts.update({f: getattr(health, f) for f in _STOP_COUNTS})
    counts.update(recovered=recovered, missed=missed)
    counts["not_logged"] = service._account.once.repeats  # problems of a shape logged before
    counts["duplicates"] = service._ledgers.duplicates  # handled already: skipped
    counts["stale"] = health.stale  # sensor messages out of order, never read: lost
    counts["repeated"] = service._times.repeated  # read already: a restarted source played again
    counts["foreign"] = health.foreign  # sensor messages of a source not their key's own
    counts["refused"] = health.refused  # refused by a handler as bad input
    counts["suppressed"] = sum(p.suppressed for p in service._publishers)  # consumers had it
    return counts


def recovery_of(subscriptions: list[Any]) -> tuple[int, int]:
    """(recovered, missed) over `subscriptions` (runtime.bus.recovery)."""
    return sum(s.recovered for s in subscriptions), sum(s.missed for s in subscriptions)


def log_recovery(service: Reporting, reported: tuple[int, int]) -> tuple[int, int]:
    """Log what publisher caches gave back since `reported`; the new figures."""
    now = recovery_of([s for s, _ in service._subscriptions])
    if now != reported:
        event(
            service.log,
            logging.INFO,
            "recovered messages from publisher caches",
            service=service.name,
            recovered=now[0],
            missed=now[1],
        )
    return now
