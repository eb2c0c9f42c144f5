"""Where a restored service takes its sensor input up again (`Service.keep_state`).

A snapshot reflects an input position: the first stamp it needs again. What comes before it was
the predecessor's, and is passed over. When the first input comes after it, the inputs in between
are gone (the source was restarted too, its log did not reach back so far). Then, if the newest
snapshot needs nothing before that input, the service is rebuilt from the newest, as a plain
restart does; otherwise the service's `on_gap` is told, to give up what it cannot derive again.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any, Generic, TypeVar

from beyond_self.core.restorable import Restorable

P = TypeVar("P", bound=Restorable)


class InputGate(Generic[P]):
    """Admits a restored service's inputs from its snapshot's position on (`admits`)."""

    def __init__(
        self,
        restored: P | None,
        newest: Callable[[], P | None],
        restore: Callable[[P | None], None],
        on_gap: Callable[[Any, int], None] | None,
    ) -> None:
        self.start = restored.stamp if restored is not None else -1
        self.newest = newest
        self.restore = restore
        self.on_gap = on_gap
        self.begun = False

    def admits(self, message: Any) -> bool:
        """Whether `message` (a sensor message with a header) is handled. On the first one past
        the snapshot's position: rebuild from the newest snapshot, or tell `on_gap(message,
        since)` that the inputs from `since` on are gone."""
        stamp: int = message.header.stamp
        if stamp < self.start:
            return False
        if self.begun or self.on_gap is None:
            self.begun = True
            return True
        self.begun = True
        newest = self.newest()
        if newest is not None and self.start < stamp <= newest.stamp:
            self.restore(newest)
            self.start = newest.stamp
            if stamp < self.start:
                self.begun = False
                return False
        if stamp > self.start >= 0:
            self.on_gap(message, self.start)
        return True


def gated(
    gate: InputGate[Any], handler: Callable[[Any], Awaitable[None] | None]
) -> Callable[[Any], Awaitable[None] | None]:
    """`handler`, called only for the messages `gate` admits."""

    def admitted(message: Any) -> Awaitable[None] | None:
        return handler(message) if gate.admits(message) else None

    return admitted
