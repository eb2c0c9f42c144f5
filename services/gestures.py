"""Gesture HMM streamer: skeleton frames in; gesture start/end events and, every frame of a
gesture, P_HMM(A | G_1^t) with the per-action log-likelihoods out.

The segmenter (`cognition.gestures.GestureSegmenter`) says when a gesture is under way and where
it began; the recogniser starts from that first frame (frames since then are kept in a bounded
buffer and caught up), so the streamed posterior is the article's P_HMM(A | G_1^t). At the end, the
final posterior is computed over exactly the segment's frames and published with `final=True`
just before the "end" event.
"""

from __future__ import annotations

from collections import deque
from pathlib import Path
from typing import Any

import numpy as np

from cognition.errors import InputError
from cognition.gestures import (
    FrameResult,
    GestureModels,
    GestureSegmenter,
    Segment,
    StreamingRecognizer,
    extract_features,
    load_models,
    recognize_sequence,
)
from cognition.gestures.default_models import default_models
from runtime.reliable import EVENT_CACHE, FRAME_CACHE
from runtime.service import Service
from schemas import ActionPosterior, GestureSegment, Header, SkeletonFrame


class GestureStreamer(Service):
    name = "gestures"
    subscribes = ("skeleton",)
    publishes = ("gesture_posterior", "gesture_segment")
    serves = ()

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
        self.buffer: deque[tuple[int, np.ndarray, Header, int]] = deque(maxlen=buffer_frames)
        self.index = 0  # frames received
        self.segment_id = 0
        self.in_gesture = False
        self.start_header: Header | None = None

    async def setup(self) -> None:
        self.gesture_models: GestureModels = (
            load_models(Path(self.models_path)) if self.models_path else default_models()
        )
        self.recognizer = StreamingRecognizer(self.gesture_models)
        self.segmenter = GestureSegmenter()
        keys = self.bus.keys
        self.posteriors = self.publisher(keys.gesture_posterior, ActionPosterior, cache=FRAME_CACHE)
        self.segments = self.publisher(keys.gesture_segment, GestureSegment, cache=EVENT_CACHE)
        self.subscribe(keys.skeleton, SkeletonFrame, self.on_frame)

    def features(self, frame: SkeletonFrame) -> np.ndarray:
        hand = frame.joints.get(self.hand_joint)
        if hand is None:
            raise InputError(
                f"skeleton frame {frame.frame} has no joint {self.hand_joint!r}; "
                f"joints: {', '.join(frame.joints) or 'none'}"
            )
        torso = frame.joints.get(self.torso_joint)
        return extract_features(hand.position, torso.position if torso else None)[0]

    def on_frame(self, frame: SkeletonFrame) -> None:
        x = self.features(frame)
        t = self.index
        self.index += 1
        self.buffer.append((t, x, frame.header, frame.frame))
        ended = self.segmenter.push(x)
        if ended is not None and self.in_gesture:
            self.finish(ended, frame.header)
        start = self.segmenter.current_start
        if start is not None and not self.in_gesture:
            self.begin(start)
        elif self.in_gesture:
            self.publish(self.recognizer.push(x), frame.header, frame.frame)

    def _since(
        self, start: int, stop: int | None = None
    ) -> list[tuple[int, np.ndarray, Header, int]]:
        return [
            item for item in self.buffer if item[0] >= start and (stop is None or item[0] < stop)
        ]

    def begin(self, start: int) -> None:
        frames = self._since(start) or [self.buffer[-1]]
        self.segment_id += 1
        self.in_gesture = True
        first = frames[0]
        self.start_header = first[2]
        self.segments.put(
            GestureSegment(
                header=self.derive(first[2], GestureSegment),
                event="start",
                segment_id=self.segment_id,
                frame=first[3],
                start_stamp=first[2].stamp,
            )
        )
        self.recognizer.reset()
        for _, x, header, number in frames:
            self.publish(self.recognizer.push(x), header, number)

    def publish(
        self, result: FrameResult, header: Header, number: int, final: bool = False
    ) -> None:
        loglik, normalized, posterior = result.loglik, result.normalized, result.posterior
        self.posteriors.put(
            ActionPosterior(
                header=self.derive(header, ActionPosterior),
                segment_id=self.segment_id,
                frame=number,
                actions=list(self.gesture_models.actions),
                posterior=[float(p) for p in posterior / posterior.sum()],
                log_likelihood=[float(v) for v in loglik],
                normalised_log_likelihood=[float(v) for v in normalized],
                final=final,
            )
        )

    def finish(self, segment: Segment, now: Header) -> None:
        frames = self._since(segment.start, segment.stop)
        self.in_gesture = False
        if not frames:
            return
        result = recognize_sequence(self.gesture_models, np.stack([f[1] for f in frames])).final
        last = frames[-1]
        self.publish(result, last[2], last[3], final=True)
        assert self.start_header is not None
        self.segments.put(
            GestureSegment(
                header=self.derive(last[2], GestureSegment),
                event="end",
                segment_id=self.segment_id,
                frame=last[3],
                start_stamp=frames[0][2].stamp,
                end_stamp=last[2].stamp,
            )
        )
