"""When a service that died is started again: the restart policy of `beyond up` and of every
`services.deployment.Deployment` (docker-compose.yml gives the containers the same).

Like systemd's `Restart=on-failure`: a service that dies (a signal, a non-zero status, or stopped
as stuck by the health watch) is started again after a delay that doubles with each restart in
the last `interval_s`, at most `burst` times in it; then the supervisor gives up and says so. A
status 0 or SIGTERM/SIGINT meant to stop; status 2 is bad input, which a restart would read
again (`RestartPreventExitStatus=2`): neither is restarted. A restarted service resumes where
its predecessor stopped (docs/concepts/recovery.md) and learns its restart count from
`BEYOND_RESTARTS` (runtime.self_report).
"""

from __future__ import annotations

import signal
from collections import deque
from dataclasses import dataclass, field

from beyond_self.core.errors import InputError

BAD_INPUT = 2  # the exit status of a service refusing its input (runtime.process)
CLEAN_SIGNALS = (signal.SIGTERM, signal.SIGINT)


@dataclass(frozen=True)
class RestartPolicy:
    """`first_delay_s` before the first restart, doubled for each restart in the last
    `interval_s` up to `max_delay_s`; at most `burst` restarts in `interval_s`."""

    first_delay_s: float = 0.1
    max_delay_s: float = 5.0
    burst: int = 5
    interval_s: float = 60.0
    prevent: tuple[int, ...] = (BAD_INPUT,)

    def __post_init__(self) -> None:
        if not (0 <= self.first_delay_s <= self.max_delay_s) or self.max_delay_s > 3600:
            raise InputError(
                f"restart delays {self.first_delay_s} s to {self.max_delay_s} s; valid: "
                "0 <= first <= max <= 3600"
            )
        if self.burst < 1 or not 0 < self.interval_s <= 86_400:
            raise InputError(
                f"{self.burst} restarts in {self.interval_s} s; valid: at least 1, in (0, 86400] s"
            )


def how_it_ended(code: int) -> str:
    """An exit code in words: "exit status 3", "killed by SIGKILL"."""
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit status {code}"


@dataclass
class Restarts:
    """One service's restarts under `policy`."""

    policy: RestartPolicy
    count: int = 0
    recent: deque[float] = field(default_factory=deque)  # when, monotonic seconds
    gave_up: str = ""

    def decide(self, code: int, stuck: bool, now: float) -> float | None:
        """The delay before starting the service again after it ended with `code` (`stuck`:
        stopped by the health watch), or None: it is not restarted (`gave_up` says why, or it
        stopped as it meant to)."""
        p = self.policy
        if not stuck:
            if code == 0 or -code in CLEAN_SIGNALS:
                return None
            if code in p.prevent:
                self.gave_up = f"{how_it_ended(code)} (bad input): not restarted"
                return None
        while self.recent and now - self.recent[0] > p.interval_s:
            self.recent.popleft()
        if len(self.recent) >= p.burst:
            self.gave_up = (
                f"{how_it_ended(code)}; gave up after {len(self.recent)} restarts in "
                f"{p.interval_s:g} s"
            )
            return None
        delay: float = min(p.max_delay_s, p.first_delay_s * 2.0 ** len(self.recent))
        self.recent.append(now)
        self.count += 1
        return delay
