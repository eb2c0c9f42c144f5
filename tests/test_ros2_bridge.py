"""The ROS 2 bridge, judged by an independent implementation of rmw_zenoh's protocol
(zenoh-ros2-sdk on PyPI: its own key expressions, type hashes, attachment parsing and rosbags
decoding) through a plain Zenoh router: `beyond up --ros2` says each sentence of a recording
once on /<robot>/description, also when the bridge is SIGKILLed in the middle."""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import subprocess
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh
from busutil_net import env_for, free_port, private_config
from rosbags.typesys import Stores, get_typestore
from zenoh_ros2_sdk.attachment import Attachment

from beyond_self.cli import main
from beyond_self.runtime.ros2_node import attachment, read_attachment
from beyond_self.schemas import ros2 as r
from beyond_self.services.launcher import BEYOND

THREE = Path(__file__).resolve().parent.parent / "recordings" / "three-actions.mcap"
STORE = get_typestore(Stores.ROS2_JAZZY)


def test_attachment_is_the_design_documents_layout() -> None:
    """8 bytes sequence number, 8 bytes source timestamp (little-endian int64), 1 byte GID
    length (16), 16 bytes GID; read back by zenoh-ros2-sdk's own parser."""
    gid = bytes(range(1, 17))
    data = attachment(7, 1_546_300_800_123_456_789, gid)
    assert len(data) == 33
    assert data[:8] == (7).to_bytes(8, "little")
    assert data[8:16] == (1_546_300_800_123_456_789).to_bytes(8, "little")
    assert data[16] == 16 and data[17:] == gid
    theirs = Attachment.from_bytes(data)
    assert (theirs.sequence_id, theirs.timestamp_ns, theirs.gid) == (
        7,
        1_546_300_800_123_456_789,
        gid,
    )
    assert read_attachment(data) == (7, 1_546_300_800_123_456_789, gid)


@contextlib.contextmanager
def plain_router(port: int) -> Iterator[zenoh.Session]:
    """A Zenoh router on loopback, nothing of ours in it (rmw_zenohd's part)."""
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps("router"))
    config.insert_json5("listen/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    config.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(config)
    try:
        yield session
    finally:
        session.close()  # type: ignore[no-untyped-call]


def expected_sentences() -> list[str]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["analyse", str(THREE)]) == 0
    said = [line.split(": ", 1)[1] for line in out.getvalue().splitlines() if ': "' in line]
    return [line.strip('"') for line in said]


def child_running(parent: int, word: str) -> int | None:
    """The pid of a child of `parent` whose command line holds `word`."""
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            cmdline = (entry / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if int(stat.rsplit(")", 1)[1].split()[1]) == parent and word.encode() in cmdline:
            return int(entry.name)
    return None


@pytest.mark.slow
def test_a_ros2_subscriber_hears_each_sentence_once_across_a_killed_bridge(
    tmp_path: Path,
) -> None:
    from zenoh_ros2_sdk import ROS2Subscriber
    from zenoh_ros2_sdk.session import ZenohSession

    port = free_port()
    config = private_config()
    topic = f"/{config.robot}/description"
    heard: list[str] = []
    first = threading.Event()

    def on_string(message: object) -> None:
        heard.append(str(message.data))  # type: ignore[attr-defined]
        first.set()

    with plain_router(port) as router:
        subscriber = ROS2Subscriber(
            topic=topic,
            msg_type=r.STRING,
            callback=on_string,
            msg_definition="string data",
            router_ip="127.0.0.1",
            router_port=port,
        )
        up = subprocess.Popen(
            [*BEYOND, "up", "--recording", str(THREE), "--ros2", "--ros2-connect",
             f"tcp/127.0.0.1:{port}", "--no-live", "--rate", "1", "--timeout", "60"],
            env=env_for(config), cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        try:
            assert first.wait(90), "no sentence reached the ROS 2 subscriber"
            # the graph as `ros2 node list` / `ros2 topic list -t` read it: liveliness tokens
            tokens = [str(reply.ok.key_expr) for reply in router.liveliness().get("@ros2_lv/0/**")
                      if reply.ok is not None]  # fmt: skip
            string_hash = STORE.hash_rihs01(r.STRING)
            node = f"NN/%/%{config.robot}/beyond_{config.robot}"
            publisher = (f"MP/%/%{config.robot}/beyond_{config.robot}/%{config.robot}%description/"
                         f"std_msgs::msg::dds_::String_/{string_hash}/::,10:,:,:,,")  # fmt: skip
            assert any(t.endswith(node) for t in tokens), tokens
            assert any(t.endswith(publisher) for t in tokens), tokens
            bridge = child_running(up.pid, "ros2")
            assert bridge is not None
            os.kill(bridge, signal.SIGKILL)
            _, err = up.communicate(timeout=120)
        finally:
            if up.poll() is None:
                up.kill()
                up.communicate()
            subscriber.close()
            ZenohSession.get_instance().close()
    assert up.returncode == 0, err[-3000:]
    assert "[up] ros2:" in err  # it died and was started again
    assert heard == expected_sentences()  # each once, in order
    assert len(heard) == 3
    said = (tmp_path / "out" / "ros2" / "said.log").read_text().splitlines()
    assert [line.split("\t")[3] for line in said] == heard
