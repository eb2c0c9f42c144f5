"""Example service 1: doubles every joint position of the skeleton stream."""

from __future__ import annotations

from beyond_self.runtime.service import Service
from beyond_self.schemas import Joint, SkeletonFrame

DOUBLED = "example/doubled"


class Doubler(Service):
    name = "doubler"

    async def setup(self) -> None:
        self.out = self.publisher(f"{self.bus.keys.root}/{DOUBLED}", SkeletonFrame)
        self.subscribe(self.bus.keys.skeleton, SkeletonFrame, self.on_frame)

    def on_frame(self, frame: SkeletonFrame) -> None:
        joints = {
            name: Joint(
                position=(2 * j.position[0], 2 * j.position[1], 2 * j.position[2]),
                confidence=j.confidence,
            )
            for name, j in frame.joints.items()
        }
        self.out.put(
            SkeletonFrame(
                header=self.derive(frame.header, SkeletonFrame),
                frame=frame.frame,
                joints=joints,
                user=frame.user,
                frame_id=frame.frame_id,
            )
        )


if __name__ == "__main__":
    Doubler.main()
