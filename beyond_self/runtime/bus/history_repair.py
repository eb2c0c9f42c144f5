"""The history a late subscriber must not lose: a workaround for zenoh-ext 1.10.

zenoh-ext's advanced subscriber can deliver a live sample before the history its per-publisher
queries bring, and then drops that history as duplicates with no miss reported
(docs/decisions.md, history-repair). Publishers number their samples from 0, so a first sample
numbered n > 0 means 0..n-1 were either dropped that way or left the cache long ago: that
publisher's samples are held, its cache is asked for them (bounded by n and by the delivery's
history), and what comes back is delivered first, in order, gaps counted as missed. A publisher
whose first sample is 0 costs nothing; one that joined late costs one quick, empty query.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field

import zenoh

from beyond_self.runtime.bus.delivery import Delivery

log = logging.getLogger("beyond.recovery")

_SOURCES_MEMORY = 4096  # publishers whose first sample was checked
_REPAIR_TIMEOUT_S = 10.0  # as zenoh-ext's own queries


@dataclass
class _Repair:
    """A publisher whose cache is being asked for what came before its first sample."""

    first: int  # sequence number of the first sample zenoh-ext delivered
    held: list[zenoh.Sample]
    found: dict[int, zenoh.Sample] = field(default_factory=dict)


class HistoryRepair:
    """Sits between zenoh-ext's advanced subscriber and `deliver`: `offer` every sample it
    delivers (serially: on Zenoh's thread, or a shared source's drain thread); `missed(count,
    key)` is told what no cache held any more."""

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        delivery: Delivery,
        deliver: Callable[[zenoh.Sample], None],
        missed: Callable[[int, str], None],
    ) -> None:
        self._session = session
        self._key = key
        self._delivery = delivery
        self._deliver = deliver
        self._missed = missed
        self._lock = threading.RLock()
        # per publisher (source id): None once its first sample is known to come after all
        # its history this subscriber could get; a _Repair while that is being checked
        self._sources: OrderedDict[str, _Repair | None] = OrderedDict()

    def offer(self, sample: zenoh.Sample) -> None:
        info = sample.source_info
        with self._lock:
            if info is not None:
                source = str(info.source_id)
                if source not in self._sources:
                    self._first_of(source, sample, int(info.source_sn))
                    return
                repair = self._sources[source]
                if repair is not None:
                    repair.held.append(sample)  # delivered after what the repair brings
                    return
            self._deliver(sample)

    def _first_of(self, source: str, sample: zenoh.Sample, sn: int) -> None:  # lock held
        if sn == 0:
            self._remember(source, None)
            self._deliver(sample)
            return
        repair = _Repair(first=sn, held=[sample])
        self._remember(source, repair)
        info = sample.source_info
        assert info is not None
        sid = info.source_id
        selector = f"{sample.key_expr}/@adv/*/{sid.zid}/{sid.eid}/**?_sn=..{sn - 1}"
        # not from this callback, which runs under zenoh-ext's own lock
        threading.Thread(
            target=self._ask_cache, args=(source, repair, selector), daemon=True
        ).start()

    def _remember(self, source: str, state: _Repair | None) -> None:
        self._sources[source] = state
        while len(self._sources) > _SOURCES_MEMORY:
            oldest, old = next(iter(self._sources.items()))
            if old is not None:
                break  # never forget a publisher whose samples are held
            del self._sources[oldest]

    def _ask_cache(self, source: str, repair: _Repair, selector: str) -> None:
        history = self._delivery.history

        def on_reply(reply: zenoh.Reply) -> None:  # Zenoh thread
            sample = reply.ok
            info = sample.source_info if sample is not None else None
            if sample is None or info is None or str(info.source_id) != source:
                return
            sn = int(info.source_sn)
            if repair.first - history <= sn < repair.first:
                with self._lock:
                    repair.found.setdefault(sn, sample)

        def on_end() -> None:
            self._repaired(source, repair)

        try:
            self._session.get(
                selector,
                zenoh.handlers.Callback(on_reply, on_end, indirect=False),
                consolidation=zenoh.ConsolidationMode.NONE,
                accept_replies=zenoh.ReplyKeyExpr.ANY,
                timeout=_REPAIR_TIMEOUT_S,
            )
        except Exception:  # the session is closing: deliver what is held
            log.debug("history check on %s not sent", self._key, exc_info=True)
            self._repaired(source, repair)

    def _repaired(self, source: str, repair: _Repair) -> None:  # any thread: the query ended
        with self._lock:
            if self._sources.get(source) is not repair:
                return
            found = sorted(repair.found.items())
            max_age = self._delivery.max_age_s
            if max_age is not None:
                oldest = time.time() - max_age
                found = [(sn, s) for sn, s in found if _sent_after(s, oldest)]
            if found:
                expected = found[0][0]
                key = str(repair.held[0].key_expr)
                for sn, sample in found:
                    if sn > expected:
                        self._missed(sn - expected, key)
                    self._deliver(sample)
                    expected = sn + 1
                if repair.first > expected:
                    self._missed(repair.first - expected, key)
                log.info(
                    "%d samples on %s recovered that zenoh-ext's history had dropped",
                    len(found),
                    self._key,
                )
            for sample in repair.held:
                self._deliver(sample)
            self._sources[source] = None


def _sent_after(sample: zenoh.Sample, oldest: float) -> bool:
    stamp = sample.timestamp
    return stamp is None or stamp.get_time().timestamp() >= oldest
