"""What went wrong in a service, counted and logged once: bad input never stops a service.

A payload that does not decode is counted as malformed; an exception of a handler, a timer, a
task, a queryable or the teardown is counted as an error. Each distinct (key, reason) is logged
once (a flood of one bad message must not become a flood of log lines), every reason is cut to
one bounded line (a hostile payload's error, a 5,000-joint frame's list of joint names, must not
become a 95 KB log line that a reader chokes on), and the last one is kept for health reports.
"""

from __future__ import annotations

import logging

from beyond_self.core.errors import InputError
from beyond_self.runtime.log import event

REASON_MAX = 500  # characters of a logged reason (and of ServiceHealth.last_error)
_MAX_REMEMBERED_REASONS = 1000


def bounded(text: str, limit: int = REASON_MAX) -> str:
    """`text` on one line of at most `limit` characters."""
    text = " ".join(text.split())
    if len(text) <= limit:
        return text
    return f"{text[: limit - 30]}... ({len(text)} characters)"


class ErrorAccount:
    def __init__(self, log: logging.Logger, service: str) -> None:
        self.log = log
        self.service = service
        self.errors = 0
        self.malformed_other = 0  # malformed input outside the subscriptions (a query)
        self.last_error = ""
        self._seen: set[tuple[str, str]] = set()

    def _first_time(self, key: str, reason: str) -> bool:
        if (key, reason) in self._seen:
            return False
        if len(self._seen) < _MAX_REMEMBERED_REASONS:
            self._seen.add((key, reason))
        return True

    def malformed(self, key: str, error: Exception) -> None:
        """A payload on `key` that does not decode (counted by its subscription)."""
        key, reason = bounded(key, 200), bounded(str(error))
        self.last_error = reason
        if self._first_time(key, reason):
            event(self.log, logging.WARNING, "malformed payload skipped", key=key, reason=reason)

    def error(self, key: str, exc: BaseException) -> None:
        """`exc` raised while handling `key`: bad input is a warning, anything else a bug."""
        self.errors += 1
        key = bounded(key, 200)
        self.last_error = bounded(f"{type(exc).__name__}: {exc}")
        if isinstance(exc, InputError):
            reason = bounded(str(exc))
            if self._first_time(key, reason):
                event(self.log, logging.WARNING, "bad input skipped", key=key, reason=reason)
        else:
            self.log.error(
                "handler failed",
                exc_info=exc,
                extra={"fields": {"key": key, "service": self.service}},
            )
