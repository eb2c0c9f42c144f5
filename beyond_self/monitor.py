"""Watching the pipeline: what `beyond up` prints and shows while the services run.

`PipelineMonitor` subscribes to the outputs of every service and feeds them to
`cognition.episodes.GestureReport`, which makes the lines `beyond analyse` prints offline. It
also keeps the state a live terminal view draws (health, posterior, prediction, description),
knows when a source has been fully described, when waiting has gone on too long
(`waited_too_long`: start-up and the tail after the source's end, never a source's silence),
and what the run lost (`losses`: gestures cut, sensor frames dropped as stale), which its
summary says and which makes `beyond up` exit non-zero.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from beyond_self.cognition.episodes import GestureReport
from beyond_self.fleet_tally import FleetTally
from beyond_self.runtime.bus.delivery import FRAMES, RELIABLE
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.bus.subscription import Received, consume
from beyond_self.runtime.clock import Clock
from beyond_self.runtime.resilience.ledger import Keeper
from beyond_self.runtime.resilience.run_state import Printed, RunState
from beyond_self.runtime.resilience.state import LedgerFile
from beyond_self.schemas import (
    ActionPosterior,
    AffordancePrediction,
    Description,
    DetectedObjects,
    GestureSegment,
    Header,
    Ledger,
    Message,
    PersonPose,
    Progress,
    ServiceHealth,
    StreamEnd,
)
from beyond_self.schemas.identity import identify

if TYPE_CHECKING:
    from beyond_self.services.deployment import Deployment

log = logging.getLogger("beyond.monitor")
LEDGER_TICK_S = 0.5  # how often a named monitor tells the per-frame results it has handled
POSE_WINDOW_S = 2.0  # a camera source's pose rate is taken over this much of its stream
NOT_DESCRIBED = "an input it needed was lost on the way; the reasoner's log says which"


class PipelineMonitor:
    """Collects each gesture's events and prints them as one block, in frame order, once the
    gesture has its final description: services run concurrently and their messages interleave
    differently from run to run, but the printed lines do not."""

    def __init__(
        self,
        bus: Bus,
        emit: Callable[[str], None],
        *,
        name: str | None = None,
        clock: Clock | None = None,
        robots: list[str] | None = None,
        state: RunState | None = None,
    ) -> None:
        self.bus = bus
        self.name = name
        # what stamps its ledgers: its deployment's clock, so that a recording of a replay
        # keeps every channel on the stream's time (a wall-clock ledger stretched its end)
        self.clock = clock or Clock()
        self.emit = emit
        self.report = GestureReport()
        self.health_reports: dict[str, ServiceHealth] = {}
        self.progress: dict[str, dict[str, int]] = {}
        self.posterior: ActionPosterior | None = None
        self.prediction: AffordancePrediction | None = None
        self.description: Description | None = None
        self.stream_end: StreamEnd | None = None
        self.frames_described = 0  # camera frames whose objects were published
        self.frames_skipped = 0  # and those a live source's object segmenter skipped
        self.poses = 0  # frames a camera source's pose model saw a person in
        self._pose_stamps: deque[int] = deque()  # those of the last POSE_WINDOW_S of stream
        self.changed = asyncio.Event()
        self.last_message = time.monotonic()
        self.moving = False  # a service has handled a sensor message, or published
        # named (its deployment's watcher), the monitor is a consumer in exactly-once: it
        # publishes what it has handled (runtime.resilience.ledger), so a restarted producer sends
        # it
        # what it lacks too. Unnamed, a belief that had reached the reasoner but not the
        # monitor when the streamer was SIGKILLed was withheld by the restarted streamer and
        # missing from the printed lines (CI, tests/test_event_time.py)
        self.ledgers = Keeper(name or "monitor", self._ledger_header)
        self._ledger_seq = 0
        self.duplicates = 0  # results received again (and not shown again)
        self.cut: dict[int, str] = {}  # gestures cancelled because their frames were lost: why
        # gestures that ended and were passed over, a later one described: an input they needed
        # (a final belief, words) was lost on the way (the reasoner's log says which)
        self.undescribed: set[int] = set()
        self.stale: dict[tuple[str, int], int] = {}  # (service, restarts): frames dropped stale
        # a fleet workstation: the robots it serves (their patterns), counted apart
        self.fleet = FleetTally(bus, robots) if robots else None
        self._tasks: list[asyncio.Task[None]] = []
        # the run this one goes on with (runtime.resilience.run_state): what it told is not
        # told again, and counts in the summary
        self.state = state
        self.previous: dict[int, Printed] = dict(state.before) if state is not None else {}
        if state is not None:
            self.ledgers.keep_on_disk(LedgerFile(state.watcher))

    @classmethod
    def of(
        cls,
        side: Deployment,
        bus: Bus,
        emit: Callable[[str], None],
        state: RunState | None = None,
    ) -> PipelineMonitor:
        """The watcher of deployment `side`: a consumer under its name, on its clock; a fleet
        workstation's also counts the gestures of the robots it serves; with `state`, it goes
        on with the run that state holds."""
        config = side.config
        robots = [p for p in (config.robots, config.standby) if p is not None]
        clock = Clock(side.clock)
        return cls(bus, emit, name=side.watcher, clock=clock, robots=robots, state=state)

    def start(self) -> None:
        keys = self.bus.keys
        loop = asyncio.get_running_loop()
        subscriptions: list[tuple[str, type[Message], Callable[[Any], None]]] = [
            (keys.gesture_segment, GestureSegment, self.on_segment),
            (keys.gesture_posterior, ActionPosterior, self.on_posterior),
            (keys.affordance, AffordancePrediction, self.on_prediction),
            (keys.description, Description, self.on_description),
            (keys.objects, DetectedObjects, self.on_objects),
            (keys.person_pose, PersonPose, self.on_pose),
            (keys.stream_end, StreamEnd, self.on_end),
            (keys.health(), ServiceHealth, self.on_health),
            (keys.progress(), Progress, self.on_progress),
        ]
        for key, cls, handler in subscriptions:
            # derived streams may cross a link (robot <-> workstation): recover what it loses
            delivery = RELIABLE if cls in (ServiceHealth, Progress) else FRAMES
            if delivery is FRAMES:
                self.ledgers.handled.declare(key)
            sub = self.bus.subscribe(key, cls, delivery)
            work = consume(sub, handler, self._failed, before=self._seen, accept=self._fresh)
            self._tasks.append(loop.create_task(work))
        if self.fleet is not None:
            self.fleet.start()
        if self.name is not None:
            self.ledgers.announce(self.bus)
            self._tasks.append(loop.create_task(self._tell_handled()))

    async def _tell_handled(self) -> None:
        """Per-frame entries go out with the next tick, as a service's go out with its health
        (a per-gesture one at once: Keeper.record)."""
        while True:
            await asyncio.sleep(LEDGER_TICK_S)
            self.ledgers.tick()

    def _ledger_header(self, cls: type[Ledger], stamp: int | None) -> Header:
        seq, self._ledger_seq = self._ledger_seq, self._ledger_seq + 1
        stamp = self.clock.now_ns() if stamp is None else stamp
        return cls.original_header(self.ledgers.name, seq, stamp)

    def _fresh(self, received: Received[Any]) -> bool:
        """Each result once (runtime.resilience.ledger): a restarted service's repeats, or a cache's
        after
        a cut link, would otherwise change the lines (a belief from an earlier frame again)."""
        ident = identify(received.key, received.message)
        if ident is None:
            return True
        told = ident.segment_id in self.previous and not isinstance(
            received.message, DetectedObjects
        )
        if self.ledgers.record(received.key, received.message) and not told:
            return True
        self.duplicates += 1
        return False

    def _seen(self, received: Received[Any]) -> None:
        self.clock.observe(received.message.header.stamp)
        if not isinstance(received.message, ServiceHealth | Progress):
            self.last_message = time.monotonic()
            self.moving = True
        self.changed.set()

    def _failed(self, key: str, exc: Exception) -> None:
        log.warning("could not show a message on %s: %s", key, exc)

    def stop(self) -> None:
        for task in self._tasks:
            task.cancel()
        if self.fleet is not None:
            self.fleet.stop()

    def _flush(self) -> None:
        lines = self.report.release()
        for n, g in self.report.gestures.items():
            if g.skipped and g.end_frame is not None and n not in self.undescribed:
                self.undescribed.add(n)
                if self.state is not None:
                    self.state.told(Printed(n, False, NOT_DESCRIBED))
        if self.state is not None:  # told before it is printed: a kill between loses no repeat
            for n, g in self.report.gestures.items():
                if g.printed and n not in self.state.before:
                    self.state.told(Printed(n, bool(g.description)))
        for line in lines:
            self.emit(line)

    # -- handlers ------------------------------------------------------------------------

    def on_pose(self, msg: PersonPose) -> None:
        self.poses += 1
        self._pose_stamps.append(msg.header.stamp)
        while msg.header.stamp - self._pose_stamps[0] > POSE_WINDOW_S * 1e9:
            self._pose_stamps.popleft()

    @property
    def pose_rate(self) -> float:
        """Poses per second over the last POSE_WINDOW_S of their stamps (0: too few yet)."""
        stamps = self._pose_stamps
        span = (stamps[-1] - stamps[0]) / 1e9 if len(stamps) > 1 else 0.0
        return (len(stamps) - 1) / span if span > 0 else 0.0

    def on_segment(self, msg: GestureSegment) -> None:
        if msg.event == "start":
            self.report.started(msg.segment_id, msg.frame)
        elif msg.event == "cancel":
            self.report.cancelled(msg.segment_id)
            if msg.cut:
                self.cut[msg.segment_id] = msg.reason
                if self.state is not None:
                    self.state.told(Printed(msg.segment_id, False, msg.reason or "cut"))
        else:
            self.report.ended(msg.segment_id, msg.frame)
        self._flush()

    def on_posterior(self, msg: ActionPosterior) -> None:
        self.posterior = msg
        if msg.final:
            self.report.believed(msg.segment_id)
            self._flush()
        else:
            self.report.belief(msg.segment_id, msg.frame, msg.actions, msg.posterior)

    def on_prediction(self, msg: AffordancePrediction) -> None:
        self.prediction = msg
        if msg.final:
            self.report.recognised(msg.segment_id, msg.action_belief, msg.evidence)
            self._flush()
        else:
            self.report.anticipation(msg.segment_id, msg.frame, msg.effects)

    def on_description(self, msg: Description) -> None:
        self.description = msg
        if msg.final and msg.sentences:
            self.report.described(msg.segment_id, msg.sentences[0].text)
            self._flush()

    def on_objects(self, msg: DetectedObjects) -> None:
        self.frames_described += 1
        self.frames_skipped += msg.skipped

    def on_progress(self, msg: Progress) -> None:
        mine = self.progress.setdefault(msg.service, {})
        for key, stamp in msg.handled.items():
            mine[key] = max(mine.get(key, -1), stamp)
            self.moving = self.moving or stamp >= 0

    def on_end(self, msg: StreamEnd) -> None:
        self.stream_end = msg

    def on_health(self, msg: ServiceHealth) -> None:
        self.health_reports[msg.service] = msg
        if msg.stale:  # each instance counts from 0: a restarted one's count adds to it
            instance = (msg.service, msg.restarts)
            self.stale[instance] = max(self.stale.get(instance, 0), msg.stale)

    async def last_health(self, timeout: float = 2.0) -> None:
        """Ask every service for its health once more before the summary: what it dropped since
        its last periodic report counts too."""
        try:
            replies = await self.bus.query(
                self.bus.keys.health(), ServiceHealth, timeout=timeout, every=True
            )
        except Exception as exc:  # the periodic reports still count
            log.warning("could not ask the services for their last health: %s", exc)
            return
        for reply in replies:
            self.on_health(reply.message)
        if self.fleet is not None:
            await self.fleet.last_health(timeout)

    # -- completion ----------------------------------------------------------------------

    def done(self, quiet_s: float = 1.0) -> bool:
        """The source is exhausted, every service reporting progress has handled its last
        message, every gesture it showed has its final description, and nothing has moved for
        `quiet_s` (a gesture ended by the source's end is announced after it)."""
        end = self.stream_end
        if end is None:
            return False
        keys = self.bus.keys
        last = {keys.stream(name): stamp for name, stamp in end.last_stamps.items()}
        for handled in self.progress.values():
            for key, stamp in handled.items():
                if key in last and stamp < last[key]:
                    return False
        if not self.report.all_ended_printed:
            return False
        return time.monotonic() - self.last_message >= quiet_s

    def waited_too_long(self, timeout_s: float, since: float, now: float | None = None) -> bool:
        """Waiting has lasted over `timeout_s` (times on `time.monotonic`'s clock): nothing has
        moved since `since` (start-up: no service has handled a sensor message or published), or
        the source has ended and nothing has moved for that long (a description that does not
        come). A source that is silent while it runs (a live camera paused, a gap in a
        recording) is never waited out."""
        now = time.monotonic() if now is None else now
        if not self.moving:
            return now - since > timeout_s
        return self.stream_end is not None and now - self.last_message > timeout_s

    def losses(self) -> list[str]:
        """What the run lost, one phrase each: gestures cut (their frames were lost: they cannot
        be described) and sensor frames dropped as stale; empty when nothing was."""
        before = {n: p.cut for n, p in self.previous.items() if p.cut}
        cut = [(f"gesture {n}", why) for n, why in sorted((before | self.cut).items())]
        stale: dict[str, int] = {}
        for (service, _), count in self.stale.items():
            stale[service] = stale.get(service, 0) + count
        if self.fleet is not None:
            cut += self.fleet.cut()
            stale.update(self.fleet.stale())
        lost = []
        if self.undescribed:
            which = ", ".join(f"gesture {n}" for n in sorted(self.undescribed))
            count = len(self.undescribed)
            lost.append(f"{count} ended but not described ({which}: {NOT_DESCRIBED})")
        if cut:
            why = "; ".join(f"{what}: {reason or 'no reason given'}" for what, reason in cut)
            lost.append(f"{len(cut)} cut (frames lost: {why})")
        if total := sum(stale.values()):
            who = ", ".join(f"{n} {c}" for n, c in sorted(stale.items()) if c)
            lost.append(f"{total} sensor frame(s) dropped as stale ({who})")
        return lost

    def summary(self) -> str:
        end = self.stream_end
        source = (
            f"source finished after {end.messages} messages ({end.dropped} dropped); "
            if end
            else ""
        )
        gestures = [g for g in self.report.gestures.values() if g.started is not None]
        described = sum(1 for g in gestures if g.description)
        total = len(gestures) + len(self.cut)
        if self.previous:  # the run this one went on with
            described += sum(1 for p in self.previous.values() if p.described)
            total += len(self.previous)
        robots = ""
        if self.fleet is not None:  # a fleet workstation: its robots' gestures, not its own
            fleet_described, fleet_total = self.fleet.counts()
            described, total = described + fleet_described, total + fleet_total
            robots = f" ({self.fleet.per_robot() or 'no robot showed one'})"
        lost = "".join(f", {what}" for what in self.losses())
        # a replay's own segmenter describes every frame; one elsewhere (a fleet's workstation)
        # keeps to the stream as it arrives, not knowing it is a recording's
        pace = "the replay, as for a live camera" if self.clock.is_recording else "the live camera"
        skipped = (
            f"; {self.frames_skipped} of {self.frames_described + self.frames_skipped} camera "
            f"frames not described, to keep up with {pace} (every gesture used them all)"
            if self.frames_skipped
            else ""
        )
        return f"{source}{described} of {total} gesture(s) described{robots}{lost}{skipped}"
