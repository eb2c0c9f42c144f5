"""Messages of valid shape and impossible meaning are malformed (issue 16): each case below was
accepted silently before, and a service then computed, buffered or logged without bound."""

from __future__ import annotations

import logging

import msgspec
import pytest
from busutil_net import skeleton_frames

import beyond_self.schemas as s
from beyond_self.runtime.error_account import REASON_MAX, ErrorAccount
from beyond_self.schemas.messages import IMAGE_BYTES_MAX, JOINTS_MAX, NAME_MAX, OBJECTS_MAX

HEADER = s.Header(version=1, source="test", seq=0, stamp=1_700_000_000_000_000_000)
INF, NAN = float("inf"), float("nan")


def _obj(**changes: object) -> s.DetectedObject:
    base = s.DetectedObject(
        id=0, centroid=(10.0, 20.0), area=100.0, colour=[0.1, 0.2], shape=[0.3], size=[0.4],
        colour_label="blue", shape_label="box", size_label="big",
    )  # fmt: skip
    return msgspec.structs.replace(base, **changes)


def _effect(**changes: object) -> s.ObjectEffect:
    base = s.ObjectEffect(
        object_id=0, object_velocity=0.1, hand_velocity=0.2, object_hand_velocity=0.1,
        contact=True, contact_duration=0.3,
    )  # fmt: skip
    return msgspec.structs.replace(base, **changes)


def _segment(**changes: object) -> s.GestureSegment:
    header = msgspec.structs.replace(HEADER, version=s.GestureSegment.VERSION)
    base = s.GestureSegment(
        header=header, event="end", segment_id=1, frame=10, start_stamp=5, end_stamp=9
    )
    return msgspec.structs.replace(base, **changes)


def _skeleton(**changes: object) -> s.SkeletonFrame:
    return msgspec.structs.replace(skeleton_frames(1)[0], **changes)


def _wire(message: s.Message, **fields: object) -> bytes:
    """`message` on the wire with `fields` changed: for what the constructor itself refuses."""
    raw = msgspec.msgpack.decode(s.encode(message))
    return msgspec.msgpack.encode({**raw, **fields})


def _objects(objects: list[s.DetectedObject]) -> s.DetectedObjects:
    header = msgspec.structs.replace(HEADER, version=s.DetectedObjects.VERSION)
    return s.DetectedObjects(header=header, frame=1, objects=objects)


def _effects(effects: list[s.ObjectEffect]) -> s.ObjectEffects:
    header = msgspec.structs.replace(HEADER, version=s.ObjectEffects.VERSION)
    return s.ObjectEffects(header=header, frame=1, effects=effects)


def _camera(n_bytes: int) -> s.CompressedCameraFrame:
    return s.CompressedCameraFrame(
        header=HEADER, timestamp=s.Time.from_ns(HEADER.stamp), frame_id="camera",
        format="jpeg", data=b"\0" * n_bytes,
    )  # fmt: skip


joint = s.Joint(position=(0.0, 0.0, 1.0))
IMPOSSIBLE: dict[str, s.Message | tuple[type[s.Message], bytes]] = {
    "frame -2^62": _skeleton(frame=-(2**62)),
    "frame 2^62": _skeleton(frame=2**62),
    "5,000 joints": _skeleton(joints={f"j{i}": joint for i in range(5000)}),
    "negative stamp": _skeleton(header=msgspec.structs.replace(HEADER, stamp=-1)),
    "infinite area": _objects([_obj(area=INF)]),
    "negative area": _objects([_obj(area=-1.0)]),
    "NaN feature": _objects([_obj(colour=[NAN])]),
    "infinite centroid": _objects([_obj(centroid=(INF, 0.0))]),
    "too many objects": _objects([_obj(id=i) for i in range(OBJECTS_MAX + 1)]),
    "NaN object speed": _effects([_effect(object_velocity=NAN)]),
    "infinite hand speed": _effects([_effect(hand_velocity=INF)]),
    "negative contact": _effects([_effect(contact_duration=-0.1)]),
    "end before start": (s.GestureSegment, _wire(_segment(), start_stamp=10, end_stamp=9)),
    "48 MiB camera frame": _camera(48 * 2**20),
    "source of 1 MB": _skeleton(header=msgspec.structs.replace(HEADER, source="s" * 2**20)),
    "NaN log-likelihood": s.ActionPosterior(
        header=HEADER,
        segment_id=0,
        frame=0,
        actions=["grasp"],
        posterior=[1.0],
        log_likelihood=[NAN],
        normalised_log_likelihood=[0.0],
    ),
    "query over 65 variables": s.AffordanceQuery(header=HEADER, query=[f"v{i}" for i in range(65)]),
    "negative likelihood": s.AffordanceQuery(header=HEADER, query=["A"], gesture={"grasp": -1.0}),
}


@pytest.mark.parametrize("case", list(IMPOSSIBLE.values()), ids=list(IMPOSSIBLE))
def test_impossible_meaning_is_malformed(case: s.Message | tuple[type[s.Message], bytes]) -> None:
    if isinstance(case, tuple):
        cls, wire = case
    else:  # constructing does not check the bounds (publishing stays cheap): decoding does
        cls, wire = type(case), s.encode(case)
    with pytest.raises(s.SchemaError):
        s.decode(wire, cls, "k")


POSSIBLE = {
    "skeleton": _skeleton(),
    "skeleton at the joint cap": _skeleton(joints={f"j{i}": joint for i in range(JOINTS_MAX)}),
    "objects": _objects([_obj(), _obj(id=1, area=0.0)]),
    "effects, hand unseen": _effects([_effect(hand_velocity=None, object_hand_velocity=None)]),
    "start": _segment(event="start", end_stamp=None),
    "end at its start": _segment(start_stamp=9, end_stamp=9),
    "camera at the byte cap": _camera(IMAGE_BYTES_MAX),
    "impossible sentence": s.Description(
        header=HEADER, segment_id=0, sentences=[s.ScoredSentence("x", -INF)], evidence=s.Evidence()
    ),
    "longest name": _skeleton(joints={"n" * NAME_MAX: joint}),
}


@pytest.mark.parametrize("message", list(POSSIBLE.values()), ids=list(POSSIBLE))
def test_possible_messages_still_decode(message: s.Message) -> None:
    assert s.decode(s.encode(message), type(message)) == message


def test_a_huge_malformed_payload_is_logged_on_one_short_line(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A 5,000-joint frame's error lists its joints (about 95 kB): the log line stays bounded."""
    account = ErrorAccount(logging.getLogger("beyond.test"), "test")  # a service's bookkeeping
    names = {f"joint_with_a_long_name_{i}": joint for i in range(5000)}
    error = s.SchemaError(f"bad frame: unknown joints {sorted(names)}")
    assert len(str(error)) > 100_000
    with caplog.at_level(logging.WARNING, "beyond.test"):
        account.malformed("k" * 10_000, error)
    (record,) = caplog.records
    assert len(record.fields["reason"]) <= REASON_MAX
    assert len(record.fields["key"]) <= 200
    assert "characters)" in record.fields["reason"]  # says it was cut, and how long it was
    assert len(account.last_error) <= REASON_MAX
