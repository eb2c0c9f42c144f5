"""Example service 2: turns the doubled skeleton into gesture start/end events (the right hand
above a height threshold), so the example is a two-stage pipeline with state."""

from __future__ import annotations

from beyond_self.runtime.service import Service
from beyond_self.schemas import GestureSegment, SkeletonFrame

THRESHOLD = 1.6  # metres, in the doubled coordinates


class Segmenter(Service):
    name = "segmenter"

    async def setup(self) -> None:
        from doubler import DOUBLED  # type: ignore[import-not-found]

        self.active: tuple[int, int] | None = None  # (segment id, start stamp)
        self.next_id = 0
        self.out = self.publisher(self.bus.keys.gesture_segment, GestureSegment)
        self.subscribe(f"{self.bus.keys.root}/{DOUBLED}", SkeletonFrame, self.on_frame)

    def on_frame(self, frame: SkeletonFrame) -> None:
        hand = frame.joints["hand_right"].position[1]
        header = self.derive(frame.header, GestureSegment)
        if self.active is None and hand > THRESHOLD:
            self.active = (self.next_id, frame.header.stamp)
            self.next_id += 1
            self.out.put(
                GestureSegment(
                    header=header,
                    event="start",
                    segment_id=self.active[0],
                    frame=frame.frame,
                    start_stamp=frame.header.stamp,
                )
            )
        elif self.active is not None and hand <= THRESHOLD:
            seg, start = self.active
            self.active = None
            self.out.put(
                GestureSegment(
                    header=header,
                    event="end",
                    segment_id=seg,
                    frame=frame.frame,
                    start_stamp=start,
                    end_stamp=frame.header.stamp,
                )
            )


if __name__ == "__main__":
    Segmenter.main()
