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


@dataclass
class GestureState:
    started: int = 0
    best: str = ""
    ended: bool = False
    anticipated: dict[str, str] = field(default_factory=dict)
    recognised: str = ""
    description: str = ""


class PipelineMonitor:
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
            sub: Subscription[Any] = self.bus.subscribe(key, cls)
            self._tasks.append(loop.create_task(self._pump(sub, handler)))

    async def _pump(self, sub: Subscription[Any], handler: Callable[[Any], None]) -> None:
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

    # -- handlers ------------------------------------------------------------------------

    def on_segment(self, msg: GestureSegment) -> None:
        g = self._gesture(msg.segment_id)
        if msg.event == "start":
            g.started = msg.frame
            self.emit(f"gesture {msg.segment_id}: started at frame {msg.frame}")
        else:
            g.ended = True
            self.emit(f"gesture {msg.segment_id}: ended at frame {msg.frame}")

    def on_posterior(self, msg: ActionPosterior) -> None:
        self.posterior = msg
        if msg.final:
            return
        g = self._gesture(msg.segment_id)
        i = max(range(len(msg.posterior)), key=msg.posterior.__getitem__)
        if msg.actions[i] != g.best:
            g.best = msg.actions[i]
            self.emit(
                f"gesture {msg.segment_id}: frame {msg.frame}, looks like {g.best} "
                f"(P_HMM {msg.posterior[i]:.2f})"
            )

    def on_prediction(self, msg: AffordancePrediction) -> None:
        self.prediction = msg
        g = self._gesture(msg.segment_id)
        if msg.final:
            action = max(msg.action_belief, key=msg.action_belief.__getitem__)
            g.recognised = action
            evidence = ", ".join(f"{k}={v}" for k, v in msg.evidence.items())
            self.emit(
                f"gesture {msg.segment_id}: recognised {action} "
                f"(P {msg.action_belief[action]:.2f}) given {evidence or 'nothing'}"
            )
            return
        if g.ended:
            return
        for var in ("ObjVel",):
            dist = msg.effects.get(var)
            if not dist:
                continue
            value = max(dist, key=dist.__getitem__)
            if dist[value] >= ANTICIPATION_THRESHOLD and g.anticipated.get(var) != value:
                g.anticipated[var] = value
                self.emit(
                    f"gesture {msg.segment_id}: anticipates {var}={value} (P {dist[value]:.2f}) "
                    f"at frame {msg.frame}, before the gesture ends"
                )

    def on_description(self, msg: Description) -> None:
        self.description = msg
        if not msg.final or not msg.sentences:
            return
        g = self._gesture(msg.segment_id)
        g.description = msg.sentences[0].text
        self.emit(f'gesture {msg.segment_id}: "{g.description}"')

    def on_end(self, msg: StreamEnd) -> None:
        self.stream_end = msg
        self.emit(f"source finished after {msg.messages} messages ({msg.dropped} dropped)")

    def on_health(self, msg: ServiceHealth) -> None:
        self.health[msg.service] = msg

    # -- completion ----------------------------------------------------------------------

    def done(self, quiet_s: float = 2.0) -> bool:
        """The source is exhausted, every gesture it showed has ended and has its final
        description, and nothing has moved for `quiet_s` (the services have caught up)."""
        if self.stream_end is None:
            return False
        if not all(g.ended and g.description for g in self.gestures.values()):
            return False
        return time.monotonic() - self.last_message >= quiet_s
