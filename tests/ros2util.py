"""rosbags' type store for the ROS 2 tests: what a third party builds its messages with."""

from __future__ import annotations

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_typestore

STORE = get_typestore(Stores.ROS2_JAZZY)


def zero(node: tuple[int, object]) -> object:
    """A field of rosbags' type store at its zero value (rosbags needs every field)."""
    kind, detail = node
    if kind == Nodetype.NAME:
        assert isinstance(detail, str)
        return STORE.types[detail](**{n: zero(sub) for n, sub in STORE.fielddefs[detail][1]})
    if kind == Nodetype.BASE:
        assert isinstance(detail, tuple)
        return "" if detail[0] == "string" else False if detail[0] == "bool" else 0
    assert isinstance(detail, tuple)
    return np.zeros(0, np.uint8) if detail[0][0] == Nodetype.BASE else []
