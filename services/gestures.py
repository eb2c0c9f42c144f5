"""Gesture HMM streamer: skeleton frames in; gesture start/end/cancel events and, every frame of a
gesture, P_HMM(A | G_1^t) with the per-action log-likelihoods out. A started gesture that turns
out to be none (drift, a tracker failure, a movement no model fits) is cancelled, and the log
says why; a skeleton frame that is not a person's hand (NaN, or metres away) is counted and
skipped.

The per-gesture logic is `cognition.episodes.GestureTracker`; this service turns messages into
its calls and its events into messages (each derived from the skeleton frame it is about: same
stamp and sequence). The end of the source (`StreamEnd`) ends or cancels a gesture still under
way once the last skeleton frame it announces has been handled, so the last gesture of a
recording is answered whatever order the end marker and the frames arrive in.

Crash-only: the tracker's checkpoint (a skeleton stamp from which its state can be rebuilt
exactly, with the segments and events counted there) goes into this service's ledger
(runtime.ledger), which the other services keep. A restarted streamer takes it, gets the
skeleton frames since back from the ingest's cache (`SKELETON` delivery), rebuilds the state
its predecessor had, and continues its numbering; what its consumers already have is not sent
again.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from beyond_self.cognition.episodes import Belief, Cancelled, Ended, GestureTracker, Started
from beyond_self.cognition.episodes.tracker import hand_position
from beyond_self.cognition.gestures import GestureModels
from beyond_self.core.errors import InputError
from beyond_self.runtime.delivery import EVENTS, FRAMES, SKELETON
from beyond_self.runtime.ledger import at_gestures, keep_newest, per_gesture
from beyond_self.runtime.log import event
from beyond_self.runtime.service import Service
from beyond_self.schemas import ActionPosterior, GestureSegment, Header, SkeletonFrame, StreamEnd
from beyond_self.services import shared

SEGMENT_KINDS = ("start", "end", "cancel")


def checkpoints_in(resume: dict[str, int]) -> dict[int, tuple[int, int]]:
    """The checkpoint per gesture count a predecessor left (`_tell_checkpoint` writes them as
    "stamp@N" and "events@N"): N -> (stamp, events)."""
    events = per_gesture(resume, "events")
    return {n: (stamp, events.get(n, 0)) for n, stamp in per_gesture(resume, "stamp").items()}


def newest_checkpoint(resume: dict[str, int]) -> tuple[int, int, int]:
    """(stamp, segments, events) of the newest checkpoint a predecessor left; -1: none."""
    return resume.get("stamp", -1), resume.get("segments", 0), resume.get("events", 0)


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
        self.checkpoint: tuple[int, int] | None = None  # the tracker's, last told
        self.events = 0
        self.finished = False

    async def setup(self) -> None:
        self.gesture_models: GestureModels = shared.gesture_models(self.models_path)
        # a restarted streamer rebuilds its predecessor's state from a checkpoint it left
        resume = self.ledgers.predecessor()
        self.history = checkpoints_in(resume)  # segments told -> (stamp, events)
        self.newest = newest_checkpoint(resume)
        self._resume_at(*self._resume_point(resume))
        self.actions = list(self.gesture_models.actions)
        keys = self.bus.keys
        self.posteriors = self.publisher(keys.gesture_posterior, ActionPosterior, FRAMES)
        self.segments = self.publisher(keys.gesture_segment, GestureSegment, EVENTS)
        self.subscribe(keys.skeleton, SkeletonFrame, self.on_frame, SKELETON, paced=True)
        self.subscribe(keys.stream_end, StreamEnd, self.on_stream_end, EVENTS)

    def _resume_at(self, stamp: int, segments: int, events: int) -> None:
        """Rebuild from the checkpoint at `stamp` (-1: from the start) with its counts."""
        self.resume_from, self.events = stamp, events
        self.tracker: GestureTracker[Header] = GestureTracker(
            self.gesture_models, buffer_frames=self.buffer_frames, first_segment_id=segments
        )
        if stamp >= 0:
            event(self.log, logging.INFO, "resuming from a checkpoint",
                  stamp=stamp, segments=segments, events=events)  # fmt: skip

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
        stamp = frame.header.stamp
        if self.finished or stamp < self.resume_from:
            return  # before the checkpoint: the predecessor's, already told
        if self.tracker.last_stamp is None and self.resume_from < stamp <= self.newest[0]:
            # going back to a checkpoint before a gesture not yet said, whose frames are gone
            # from the source's cache (the source was restarted too), while the newest one's
            # are here: rebuild exactly from the newest, as a plain restart does (the gestures
            # in between are with the consumers, or lost either way). From here instead, the
            # cut path below left the gesture under way started and never ended: every
            # consumer waited on it (the kill test stalled)
            self._resume_at(*self.newest)
            if stamp < self.resume_from:
                return
        if self.tracker.last_stamp is None and stamp > self.resume_from >= 0:
            self._cut(frame)
        x = self.features(frame)
        events = self.events
        self.emit(self.tracker.push(stamp, frame.frame, x, frame.header))
        checkpoint = self.tracker.checkpoint
        if checkpoint is not None and checkpoint != self.checkpoint:
            # a checkpoint moves only on a frame with no event (or is the first frame): the
            # events counted before this frame are those before the checkpoint's
            self.checkpoint = checkpoint
            self._tell_checkpoint(*checkpoint, events)
        if self.end_at is not None and stamp >= self.end_at:
            self.finish()

    def _cut(self, frame: SkeletonFrame) -> None:
        """The frames since the checkpoint are gone (the source was restarted too): cancel
        each gesture a consumer saw start and none saw end, whose frames no one can give back
        (consumers would wait on it for ever), and number on after every gesture a consumer
        has."""
        key = self.bus.keys.gesture_segment
        seen = self.ledgers.seen_downstream(key, SEGMENT_KINDS)
        closed = self.ledgers.seen_downstream(key, ("end", "cancel"))
        cut = sorted(seen - closed)
        stamp = frame.header.stamp
        reason = f"its frames before {stamp} are gone (source and streamer restarted)"
        self.emit([
            Cancelled(segment_id=n, frame=frame.frame, start_stamp=self.resume_from,
                      ref=frame.header, reason=reason)
            for n in cut
        ])  # fmt: skip
        self.tracker.segment_id = max(self.tracker.segment_id, *seen, 0)
        self.report_error(
            "resume",
            InputError(
                f"the skeleton cache starts at {stamp}, after the checkpoint "
                f"{self.resume_from}: gestures under way were cut ({cut})"
            ),
        )

    def _tell_checkpoint(self, at: int, segments: int, events: int) -> None:
        """The newest checkpoint, and the newest one at each of the last gesture counts: a
        successor goes back to the one before the oldest gesture not yet said (its outputs
        may have died with the workstation that was working on them, caches and all)."""
        first_after_gesture = segments not in self.history
        self.history[segments] = (at, events)
        keep_newest(self.history)
        points = self.history.items()
        stamps = {"stamp": at} | at_gestures("stamp", {n: a for n, (a, _) in points})
        counts = {"segments": segments, "events": events}
        counts |= at_gestures("events", {n: e for n, (_, e) in points})
        self.ledgers.checkpoint(stamps, counts, {self.bus.keys.skeleton: at})
        if first_after_gesture:
            # told at once, not with the next health report: at rate max a second of wall
            # time is many gestures, and a successor whose newest checkpoint is older than the
            # source's cache cannot rebuild exactly (on_frame)
            self.ledgers.publish()

    def _resume_point(self, resume: dict[str, int]) -> tuple[int, int, int]:
        """(stamp, segments, events) to start from: the newest checkpoint left, or, when the
        gestures it has told are not all said yet (a workstation taken over: the outputs in
        between are gone), the newest one before the oldest gesture not said. -1: none."""
        latest = self.newest
        points = self.history
        unsaid = self.ledgers.unsaid(self.bus.keys.description, range(1, latest[1] + 1))
        if not points or not unsaid:
            return latest
        before = [n for n in points if n < min(unsaid)] or [min(points)]
        stamp, events = points[max(before)]
        return stamp, max(before), events

    def published_counts(self) -> dict[str, int]:
        # events carry their running count (event_seq), which a restarted streamer continues:
        # consumers compare it with what they received
        return {**super().published_counts(), self.bus.keys.gesture_segment: self.events}

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
                self.events += 1
                self.segments.put(
                    GestureSegment(
                        event_seq=self.events,
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
                self.events += 1
                self.segments.put(
                    GestureSegment(
                        event_seq=self.events,
                        header=self.derive(ev.ref, GestureSegment),
                        event="end" if ended else "cancel",
                        segment_id=ev.segment_id,
                        frame=ev.frame,
                        start_stamp=ev.start_stamp,
                        end_stamp=ev.end_stamp if isinstance(ev, Ended) else None,
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
