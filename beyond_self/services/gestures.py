"""Gesture HMM streamer: skeleton frames in; gesture start/end/cancel events and, every frame of a
gesture, P_HMM(A | G_1^t) with the per-action log-likelihoods out.

The per-gesture logic is `cognition.episodes.GestureTracker`; this service turns messages into
its calls and its events into messages, each derived from the skeleton frame it is about. The
source's `StreamEnd` closes a gesture still under way once the last frame it announces is
handled, whatever order they arrive in. Crash-only: the base keeps the tracker's snapshot
(`Service.keep_state`), from which a restarted streamer goes on with the frames since, its
events numbered on (docs/concepts/recovery.md).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any

import msgspec
import numpy as np

from beyond_self.cognition.episodes import Belief, Cancelled, Ended, GestureTracker, Started
from beyond_self.cognition.episodes.tracker import TrackerSnapshot, hand_position
from beyond_self.cognition.gestures import GestureModels
from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.delivery import EVENTS, FRAMES, SKELETON
from beyond_self.runtime.log import event
from beyond_self.runtime.service import Service
from beyond_self.schemas import ActionPosterior, GestureSegment, Header, SkeletonFrame, StreamEnd
from beyond_self.services import shared

SEGMENT_KINDS = ("start", "end", "cancel")


class GestureStreamer(Service):
    name = "gestures"
    subscribes = ("skeleton", "stream_end")
    publishes = ("gesture_posterior", "gesture_segment")
    serves = ()
    fleet = True  # a workstation may serve many robots with one process (runtime.fleet)

    def __init__(
        self,
        *,
        models: str | None = None,
        hand_joint: str = "right_hand",
        torso_joint: str = "torso",
        buffer_frames: int = 1800,
        **base: Any,
    ) -> None:
        super().__init__(**base)
        self.models_path = models
        self.hand_joint = hand_joint
        self.torso_joint = torso_joint
        self.buffer_frames = buffer_frames
        self.end_at: int | None = None  # last skeleton stamp of the source, once it has ended
        self.finished = False

    @classmethod
    def warm(cls, options: Mapping[str, Any]) -> None:
        shared.gesture_models(options.get("models"))

    async def setup(self) -> None:
        self.gesture_models: GestureModels = shared.gesture_models(self.models_path)
        self.actions = list(self.gesture_models.actions)
        keys = self.bus.keys
        self.keep_state(
            TrackerSnapshot,
            self.restore,
            lambda: self.tracker.snapshot(),
            inputs=[keys.skeleton],
            on_gap=self.frames_lost,
        )
        self.posteriors = self.publisher(keys.gesture_posterior, ActionPosterior, FRAMES)
        self.segments = self.publisher(keys.gesture_segment, GestureSegment, EVENTS)
        self.subscribe(keys.skeleton, SkeletonFrame, self.on_frame, SKELETON, paced=True)
        self.subscribe(keys.stream_end, StreamEnd, self.on_stream_end, EVENTS)

    def restore(self, state: TrackerSnapshot | None) -> None:
        """Rebuild from `state` (None: from the first frame)."""
        self.tracker: GestureTracker[Header] = GestureTracker.restored(
            self.gesture_models, state, self.buffer_frames
        )
        if state is not None:
            event(
                self.log, logging.INFO, "resuming from a snapshot", **msgspec.structs.asdict(state)
            )

    def features(self, frame: SkeletonFrame) -> np.ndarray:
        hand = frame.joints.get(self.hand_joint)
        if hand is None:
            names = list(frame.joints)
            shown = ", ".join(names[:8]) + (f", … ({len(names)} in all)" if len(names) > 8 else "")
            raise InputError(
                f"skeleton frame {frame.frame} has no joint {self.hand_joint!r}; "
                f"joints: {shown or 'none'}"
            )
        torso = frame.joints.get(self.torso_joint)
        return hand_position(
            hand.position, torso.position if torso else None, f"skeleton frame {frame.frame}"
        )

    def on_frame(self, frame: SkeletonFrame) -> None:
        if self.finished:
            return
        stamp = frame.header.stamp
        x = self.features(frame)
        self.emit(self.tracker.push(stamp, frame.frame, x, frame.header))
        if self.end_at is not None and stamp >= self.end_at:
            self.finish()

    def frames_lost(self, frame: SkeletonFrame, since: int) -> None:
        """The frames from `since` to `frame` are gone (source and streamer restarted): cancel
        each gesture a consumer saw start and none saw end (they would wait on it for ever)."""
        downstream = self.downstream(self.bus.keys.gesture_segment)
        seen = downstream.seen(*SEGMENT_KINDS)
        under_way = seen - downstream.seen("end", "cancel")
        stamp = frame.header.stamp
        reason = f"its frames before {stamp} are gone (source and streamer restarted)"
        self.emit(
            self.tracker.frames_lost(
                under_way, max(seen, default=0), frame.frame, since, frame.header, reason
            )
        )
        why = f"the skeleton stream starts again at {stamp}, after the snapshot's {since}"
        self.report_error("resume", InputError(f"{why}: gestures cut {sorted(under_way)}"))

    def published_counts(self) -> dict[str, int]:
        # events carry their running count (event_seq), which a restarted streamer continues:
        # consumers compare it with what they received
        return {**super().published_counts(), self.bus.keys.gesture_segment: self.tracker.events}

    def on_stream_end(self, msg: StreamEnd) -> None:
        last = msg.last_stamps.get("skeleton")
        self.end_at = last if last is not None else -1
        last_seen = self.tracker.last_stamp
        if last is None or (last_seen is not None and last_seen >= last):
            self.finish()

    def finish(self) -> None:
        if not self.finished:
            self.finished = True
            self.emit(self.tracker.finish())

    def emit(self, events: list[Any]) -> None:
        for ev in events:
            if isinstance(ev, Belief):
                self.publish_belief(ev)
            elif isinstance(ev, Started):
                self.segments.put(
                    GestureSegment(
                        event_seq=ev.seq,
                        header=self.derive(ev.ref, GestureSegment),
                        event="start",
                        segment_id=ev.segment_id,
                        frame=ev.frame,
                        start_stamp=ev.stamp,
                    )
                )
            elif isinstance(ev, Ended | Cancelled):
                ended = isinstance(ev, Ended)
                if isinstance(ev, Cancelled):  # why a started gesture is not described
                    why = {"segment": ev.segment_id, "frame": ev.frame, "reason": ev.reason}
                    event(self.log, logging.INFO, "gesture cancelled", **why)
                self.segments.put(
                    GestureSegment(
                        event_seq=ev.seq,
                        header=self.derive(ev.ref, GestureSegment),
                        event="end" if ended else "cancel",
                        segment_id=ev.segment_id,
                        frame=ev.frame,
                        start_stamp=ev.start_stamp,
                        end_stamp=ev.end_stamp if isinstance(ev, Ended) else None,
                        reason=ev.reason if isinstance(ev, Cancelled) else "",
                        cut=isinstance(ev, Cancelled) and ev.cut,
                    )
                )

    def publish_belief(self, ev: Belief[Header]) -> None:
        r = ev.result
        self.posteriors.put(
            ActionPosterior(
                header=self.derive(ev.ref, ActionPosterior),
                segment_id=ev.segment_id,
                frame=ev.frame,
                actions=self.actions,
                posterior=ev.posterior,
                log_likelihood=r.loglik.tolist(),
                normalised_log_likelihood=r.normalized.tolist(),
                final=ev.final,
            )
        )
