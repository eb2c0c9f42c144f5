"""Watching the pipeline: what `beyond up` prints and shows while the services run.

`PipelineMonitor` subscribes to the outputs of every service and turns them into event lines
that depend only on message contents (a run prints the same lines every time): a gesture starts,
the recognised action changes, an effect is anticipated before the gesture ends, the gesture is
recognised, its description. It also keeps the state a live terminal view draws (per-service
health, current action posterior, effect prediction, last description), and knows when a
replayed source has been fully described.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from runtime.bus import Bus, Subscription
from runtime.reliable import ReliableSubscription, reliable_subscription
from schemas import (
    ActionPosterior,
    AffordancePrediction,
    Description,
    GestureSegment,
    Message,
    ServiceHealth,
    StreamEnd,
)

ANTICIPATION_THRESHOLD = 0.6  # an effect value this probable counts as anticipated


# order of event kinds within one frame of a gesture's block
STARTED, LOOKS, ANTICIPATES, ENDED, RECOGNISED, DESCRIBED = range(6)


@dataclass
class GestureState:
    started: int = 0
    best: str = ""
    end_frame: int | None = None
    anticipated: dict[str, str] = field(default_factory=dict)
    recognised: str = ""
    description: str = ""
    events: list[tuple[int, int, str]] = field(default_factory=list)  # (frame, kind, text)
    printed: bool = False

    @property
    def ended(self) -> bool:
        return self.end_frame is not None

    def block(self) -> list[str]:
        """The gesture's lines in frame order; anticipations count only before the end."""
        end = self.end_frame if self.end_frame is not None else 1 << 62
        kept = [e for e in self.events if e[1] != ANTICIPATES or e[0] <= end]
        return [text for _, _, text in sorted(kept, key=lambda e: (e[0], e[1]))]


class PipelineMonitor:
    """Collects each gesture's events and prints them as one block, in frame order, once the
    gesture has its final description: services run concurrently and their messages interleave
    differently from run to run, but the printed lines do not."""

    def __init__(self, bus: Bus, emit: Callable[[str], None]) -> None:
        self.bus = bus
        self.emit = emit
        self.gestures: dict[int, GestureState] = {}
        self.health: dict[str, ServiceHealth] = {}
        self.posterior: ActionPosterior | None = None
        self.prediction: AffordancePrediction | None = None
        self.description: Description | None = None
        self.stream_end: StreamEnd | None = None
        self.changed = asyncio.Event()
        self.last_message = time.monotonic()
        self._tasks: list[asyncio.Task[None]] = []

    def start(self) -> None:
        keys = self.bus.keys
        loop = asyncio.get_running_loop()
        subscriptions: list[tuple[str, type[Message], Callable[[Any], None]]] = [
            (keys.gesture_segment, GestureSegment, self.on_segment),
            (keys.gesture_posterior, ActionPosterior, self.on_posterior),
            (keys.affordance, AffordancePrediction, self.on_prediction),
            (keys.description, Description, self.on_description),
            (keys.stream_end, StreamEnd, self.on_end),
            (keys.health(), ServiceHealth, self.on_health),
        ]
        for key, cls, handler in subscriptions:
            # derived streams may cross a link (robot <-> workstation): recover what it loses
            sub: Subscription[Any] | ReliableSubscription[Any] = (
                self.bus.subscribe(key, cls)
                if cls is ServiceHealth
                else reliable_subscription(self.bus, key, cls)
            )
            self._tasks.append(loop.create_task(self._pump(sub, handler)))

    async def _pump(
        self, sub: Subscription[Any] | ReliableSubscription[Any], handler: Callable[[Any], None]
    ) -> None:
        async for received in sub:
            handler(received.message)
            if not isinstance(received.message, ServiceHealth):
                self.last_message = time.monotonic()
            self.changed.set()

    def stop(self) -> None:
        for task in self._tasks:
            task.cancel()

    def _gesture(self, segment_id: int) -> GestureState:
        return self.gestures.setdefault(segment_id, GestureState())

    def _flush(self) -> None:
        """Print every complete gesture whose predecessors are printed."""
        for segment_id in sorted(self.gestures):
            g = self.gestures[segment_id]
            if g.printed:
                continue
            if not (g.ended and g.recognised and g.description):  # any arrival order
                return
            for line in g.block():
                self.emit(f"gesture {segment_id}: {line}")
            g.printed = True

    # -- handlers ------------------------------------------------------------------------

    def on_segment(self, msg: GestureSegment) -> None:
        g = self._gesture(msg.segment_id)
        if msg.event == "start":
            g.started = msg.frame
            g.events.append((msg.frame, STARTED, f"started at frame {msg.frame}"))
        else:
            g.end_frame = msg.frame
            g.events.append((msg.frame, ENDED, f"ended at frame {msg.frame}"))
            self._flush()

    def on_posterior(self, msg: ActionPosterior) -> None:
        self.posterior = msg
        if msg.final:
            return
        g = self._gesture(msg.segment_id)
        i = max(range(len(msg.posterior)), key=msg.posterior.__getitem__)
        if msg.actions[i] != g.best:
            g.best = msg.actions[i]
            text = f"frame {msg.frame}, looks like {g.best} (P_HMM {msg.posterior[i]:.2f})"
            g.events.append((msg.frame, LOOKS, text))

    def on_prediction(self, msg: AffordancePrediction) -> None:
        self.prediction = msg
        g = self._gesture(msg.segment_id)
        if msg.final:
            action = max(msg.action_belief, key=msg.action_belief.__getitem__)
            g.recognised = action
            evidence = ", ".join(f"{k}={v}" for k, v in msg.evidence.items())
            text = (
                f"recognised {action} (P {msg.action_belief[action]:.2f}) "
                f"given {evidence or 'nothing'}"
            )
            g.events.append((1 << 62, RECOGNISED, text))
            self._flush()
            return
        for var in ("ObjVel",):
            dist = msg.effects.get(var)
            if not dist:
                continue
            value = max(dist, key=dist.__getitem__)
            if dist[value] >= ANTICIPATION_THRESHOLD and g.anticipated.get(var) != value:
                g.anticipated[var] = value
                text = (
                    f"anticipates {var}={value} (P {dist[value]:.2f}) at frame {msg.frame}, "
                    "before the gesture ends"
                )
                g.events.append((msg.frame, ANTICIPATES, text))

    def on_description(self, msg: Description) -> None:
        self.description = msg
        if not msg.final or not msg.sentences:
            return
        g = self._gesture(msg.segment_id)
        g.description = msg.sentences[0].text
        g.events.append((1 << 62, DESCRIBED, f'"{g.description}"'))
        self._flush()

    def on_end(self, msg: StreamEnd) -> None:
        self.stream_end = msg

    def on_health(self, msg: ServiceHealth) -> None:
        self.health[msg.service] = msg

    # -- completion ----------------------------------------------------------------------

    def done(self, quiet_s: float = 2.0) -> bool:
        """The source is exhausted, every gesture it showed has ended and has its final
        description, and nothing has moved for `quiet_s` (the services have caught up)."""
        if self.stream_end is None:
            return False
        if not all(g.printed for g in self.gestures.values()):
            return False
        return time.monotonic() - self.last_message >= quiet_s

    def summary(self) -> str:
        end = self.stream_end
        source = (
            f"source finished after {end.messages} messages ({end.dropped} dropped); "
            if end
            else ""
        )
        described = sum(1 for g in self.gestures.values() if g.description)
        return f"{source}{described} of {len(self.gestures)} gesture(s) described"
