"""Where a restarted source plays from: the runtime's resume plan for a source service.

A source (the ingest) asks for it once its player has heard every consumer's `Progress`
(runtime.recording.pacing): what every consumer has handled, per sensor key, moved back to the
oldest input position any consumer's snapshot needs (a consumer restarted with the source finds
those inputs nowhere else). A source restarted together with all its consumers (the deployment
killed whole) goes back to the oldest gesture some consumer saw start and not every consumer of
descriptions heard said. The source sends what comes after the plan's stamp on each key, after
playing again, from its source log, what is between (runtime.resilience.source_log).
"""

from __future__ import annotations

from collections.abc import Mapping

import msgspec

from beyond_self.runtime.resilience.ledger import Keeper


class ResumePlan(msgspec.Struct, frozen=True):
    """`after`: sensor key -> the stamp up to which nothing is sent again (-1: from the start);
    `restarted`: a predecessor's record was found (its log holds what is between)."""

    after: dict[str, int]
    restarted: bool = False

    def fresh(self, key: str, stamp: int) -> bool:
        """Whether a message of `key` stamped `stamp` is to be sent."""
        return stamp > self.after.get(key, -1)

    @property
    def start(self) -> int | None:
        """The earliest stamp played from (None: no sensor key)."""
        return min(self.after.values(), default=None)

    def play_from(self) -> dict[str, int]:
        """Sensor key -> the first stamp to send."""
        return {key: stamp + 1 for key, stamp in self.after.items()}


def plan(
    keeper: Keeper, consumers_have: Mapping[str, int], segment_key: str, said_key: str
) -> ResumePlan:
    """The plan of a source whose consumers have handled `consumers_have` (sensor key ->
    stamp); `segment_key`, `said_key`: the gesture events' and the descriptions' keys."""
    after = dict(consumers_have)
    for key, stamp in keeper.book.needed(after).items():
        after[key] = min(after[key], stamp - 1)
    restarted = keeper.instance > 0
    if restarted and all(s < 0 for s in after.values()):
        # every consumer starts afresh too: they go back to the oldest gesture not said yet,
        # and need its frames again
        started = keeper.seen_downstream(segment_key, ("start",))
        unsaid = min(keeper.unsaid(said_key, started), default=None)
        after.update({k: s - 1 for k, s in keeper.book.needed(after, unsaid).items()})
    return ResumePlan(after, restarted)
