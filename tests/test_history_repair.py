"""A late subscriber must get a running publisher's history even when live samples win the race
against the per-publisher history query (zenoh-ext 1.10).

zenoh-ext's AdvancedSubscriber holds a publisher's live samples back only while its *global*
history query (`<key>/@adv/**`) is pending. Its per-publisher queries (the one sent when the
publisher's liveliness token is detected, `detect_late_publishers`, and the gap query sent when
a live sample was parked) hold nothing back: if the global query ends first and a live sample
comes before they end, that sample is delivered as the publisher's first, and every history
reply, older, is then discarded as a duplicate, with no miss reported. On a loaded machine the
window is a few tens of ms wide, enough for a per-frame stream (the CI failure of
test_deploy_netns.py::test_the_robot_may_start_first). Here a second queryable on the
publisher's side delays the end of per-publisher queries, which widens the window at will;
runtime.bus.history_repair must still get the history back."""

from __future__ import annotations

import asyncio
import threading
import time

import zenoh
from busutil_net import private_config, skeleton_frames

import beyond_self.schemas as s
from beyond_self.runtime.bus.delivery import FRAMES
from beyond_self.runtime.bus.session import Bus

BEFORE = 100  # published before the subscriber exists: only the cache holds them
LIVE = 60  # published while it starts, every 10 ms
SLOW_S = 0.5  # per-publisher queries end this late


def _slow_per_publisher_queries(session: zenoh.Session, key: str) -> zenoh.Queryable[None]:
    """A queryable beside the publisher's cache that answers nothing, but ends per-publisher
    queries (not the global `<key>/@adv/**` one) only SLOW_S later."""

    def on_query(query: zenoh.Query) -> None:
        if str(query.key_expr).endswith("@adv/**"):
            return

        def later() -> None:
            time.sleep(SLOW_S)
            with query:  # dropping the query sends its final reply
                pass

        threading.Thread(target=later, daemon=True).start()

    return session.declare_queryable(f"{key}/@adv/pub/**", on_query)


async def test_history_survives_live_samples_arriving_before_the_per_publisher_query_ends() -> None:
    config = private_config()
    frames = skeleton_frames(BEFORE + LIVE)
    with Bus.open(config) as robot, Bus.open(config) as ws:
        key = robot.keys.skeleton
        pub = robot.publisher(key, s.SkeletonFrame, FRAMES)
        slow = _slow_per_publisher_queries(robot.session, key)
        for frame in frames[:BEFORE]:
            pub.put(frame)
        stop = threading.Event()

        def live() -> None:
            for frame in frames[BEFORE:]:
                if stop.is_set():
                    return
                pub.put(frame)
                time.sleep(0.01)

        thread = threading.Thread(target=live, daemon=True)
        thread.start()
        try:
            sub = ws.subscribe(key, s.SkeletonFrame, FRAMES)
            got: list[int] = []
            while len(got) < BEFORE + LIVE:
                try:
                    got.append((await sub.recv(timeout=3)).message.frame)
                except TimeoutError:
                    break
            # every frame once, in order, the history included
            assert got == list(range(BEFORE + LIVE)), (got[:3], len(got), sub.missed)
            assert sub.missed == 0
        finally:
            stop.set()
            thread.join()
            slow.undeclare()
            pub.close()
            await asyncio.sleep(0)
