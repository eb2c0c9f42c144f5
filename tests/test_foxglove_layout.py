"""The shipped Foxglove layout is the one `runtime.foxglove.layout` builds, and shows only
topics the bridge serves (so importing it gives panels with data, not empty ones)."""

from __future__ import annotations

import json
import re

from busutil_net import REPO

from beyond_self.runtime.foxglove.layout import layout_json
from beyond_self.runtime.foxglove.views import VIEWS
from beyond_self.schemas.keys import STREAMS, Keys

SHIPPED = REPO / "deploy" / "foxglove" / "beyond-demo.layout.json"


def test_shipped_layout_is_the_built_one() -> None:
    assert SHIPPED.read_text(encoding="utf-8") == layout_json("robot"), (
        "regenerate: beyond foxglove --layout deploy/foxglove/beyond-demo.layout.json"
    )


def test_layout_shows_served_topics_of_its_robot() -> None:
    keys = Keys("r2")
    served = {f"{keys.root}/{suffix}" for suffix, _ in STREAMS.values()}
    served |= {v.topic(keys.root) for v in VIEWS}
    text = layout_json("r2")
    json.loads(text)
    shown = set(re.findall(r"beyond/[A-Za-z0-9_.-]+/[A-Za-z0-9_/]+", text))
    assert shown and shown <= served, shown - served
    for view in ("scene", "objects", "pose", "posterior", "affordance", "log"):
        assert f"{keys.root}/foxglove/{view}" in shown
    assert keys.camera_compressed in shown and keys.person_camera in shown
    assert "beyond/robot/" not in text
