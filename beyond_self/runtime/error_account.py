"""What went wrong in a service, counted and logged once: bad input never stops a service.

A payload that does not decode is counted as malformed; an exception of a handler, a timer, a
task, a queryable or the teardown as an error. Each distinct problem is logged once per key, cut
to one bounded line (a hostile payload must not become a flood of log lines, nor a 95 KB one),
and the last is kept for health. "Distinct" is what went wrong, not which message: reasons are
compared with every number taken out (`shape`), so the same complaint about frames 363 and 364
is one problem. The ones not logged are counted (`repeats`) and their total logged at the end.
"""

from __future__ import annotations

import logging
import re

from beyond_self.core.errors import InputError
from beyond_self.runtime.log import event

REASON_MAX = 500  # characters of a logged reason (and of ServiceHealth.last_error)
_MAX_REMEMBERED_REASONS = 1000
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def bounded(text: str, limit: int = REASON_MAX) -> str:
    """`text` on one line of at most `limit` characters."""
    text = " ".join(text.split())
    if len(text) <= limit:
        return text
    return f"{text[: limit - 30]}... ({len(text)} characters)"


def shape(reason: str) -> str:
    """`reason` with every number replaced by '#': what went wrong, whichever message it was."""
    return _NUMBER.sub("#", reason)


class LogOnce:
    """Says whether a (key, reason) is the first of its shape: the one rule by which services
    and the recorder decide what to log. Remembers at most _MAX_REMEMBERED_REASONS shapes
    (beyond that, new ones are logged every time rather than remembered without bound)."""

    def __init__(self) -> None:
        self._seen: set[tuple[str, str]] = set()
        self.repeats = 0  # occurrences not logged because one of the same shape was

    def first(self, key: str, reason: str) -> bool:
        item = (key, shape(reason))
        if item in self._seen:
            self.repeats += 1
            return False
        if len(self._seen) < _MAX_REMEMBERED_REASONS:
            self._seen.add(item)
        return True


class ErrorAccount:
    def __init__(self, log: logging.Logger, service: str) -> None:
        self.log = log
        self.service = service
        self.errors = 0
        self.malformed_other = 0  # malformed input outside the subscriptions (a query)
        self.last_error = ""
        self.once = LogOnce()

    def malformed(self, key: str, error: Exception) -> None:
        """A payload on `key` that does not decode (counted by its subscription)."""
        key, reason = bounded(key, 200), bounded(str(error))
        self.last_error = reason
        if self.once.first(key, reason):
            event(self.log, logging.WARNING, "malformed payload skipped", key=key, reason=reason)

    def error(self, key: str, exc: BaseException) -> None:
        """`exc` raised while handling `key`: bad input is a warning, anything else a bug."""
        self.errors += 1
        key = bounded(key, 200)
        self.last_error = bounded(f"{type(exc).__name__}: {exc}")
        if isinstance(exc, InputError):
            reason = bounded(str(exc))
            if self.once.first(key, reason):
                event(self.log, logging.WARNING, "bad input skipped", key=key, reason=reason)
        else:
            self.log.error(
                "handler failed",
                exc_info=exc,
                extra={"fields": {"key": key, "service": self.service}},
            )

    def refused(self, key: str, reason: str) -> None:
        """A message on `key` refused before its handler (not an error of this service): said
        once per shape of `reason`, counted by the caller."""
        key, reason = bounded(key, 200), bounded(reason)
        if self.once.first(key, reason):
            event(self.log, logging.WARNING, "message refused", key=key, reason=reason)
