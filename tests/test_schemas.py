"""Schemas: round trips, strict decoding, JSON Schema export, keys."""

from __future__ import annotations

import json

import jsonschema
import msgspec
import pytest
from busutil_net import health_report
from hypothesis import given, settings
from hypothesis import strategies as st
from third_party_readers import unbounded_integers, unsafe_integers

import beyond_self.schemas as s
from beyond_self.core.errors import InputError
from beyond_self.schemas import codec
from beyond_self.schemas.base import STAMP_MARK
from beyond_self.schemas.messages import IMAGE_BYTES_MAX

H = s.Header(version=1, source="test", seq=7, stamp=1_700_000_000_123_456_789, correlation="x/1")


def _h(cls: type[s.Message]) -> s.Header:
    """H at the version `cls` is read at (decoding refuses any other)."""
    return msgspec.structs.replace(H, version=cls.VERSION)


def examples() -> list[s.Message]:
    return [
        s.SkeletonFrame(header=H, frame=3, joints={"hand_right": s.Joint((0.1, -0.2, 1.5), 0.5)}),
        s.CameraFrame.build(H, 4, 2, bytes(range(24))),
        s.CompressedCameraFrame(
            header=H,
            timestamp=s.Time.from_ns(H.stamp),
            frame_id="camera",
            format="png",
            data=b"\x89PNG",
        ),
        s.PersonPose(
            header=H,
            frame=3,
            width=176,
            height=144,
            keypoints={
                "head": s.Keypoint(position=(88.5, 40.25), confidence=0.99),
                "right_hand": s.Keypoint(position=(60.0, 250.0), confidence=0.1),
            },
        ),
        s.DetectedObjects(
            header=_h(s.DetectedObjects),
            frame=3,
            objects=[
                s.DetectedObject(
                    id=1,
                    centroid=(10.0, 20.0),
                    area=300.0,
                    colour=[0.1, 0.9, 0.2],
                    shape=[0.8, 0.3],
                    size=[300.0],
                    colour_label="green1",
                    shape_label="box",
                    size_label="small",
                )
            ],
        ),
        s.ObjectEffects(
            header=_h(s.ObjectEffects),
            frame=3,
            effects=[
                s.ObjectEffect(
                    object_id=1,
                    object_velocity=0.2,
                    hand_velocity=0.5,
                    object_hand_velocity=0.3,
                    contact=True,
                    contact_duration=0.4,
                    labels={"ObjVel": "slow", "Contact": "short"},
                )
            ],
        ),
        s.GestureSegment(
            header=_h(s.GestureSegment),
            event="end",
            segment_id=2,
            frame=9,
            start_stamp=1,
            end_stamp=5,
        ),
        s.GestureObject(
            header=H, segment_id=2, frame=4, labels={"Color": "blue", "Shape": "box"}, reason=""
        ),
        s.ActionPosterior(
            header=H,
            segment_id=2,
            frame=9,
            actions=["grasp", "tap", "touch"],
            posterior=[0.2, 0.5, 0.3],
            log_likelihood=[-30.0, -29.1, -29.6],
            normalised_log_likelihood=[-3.0, -2.91, -2.96],
        ),
        s.AffordancePrediction(
            header=H,
            segment_id=2,
            frame=9,
            action_belief={"tap": 0.7, "grasp": 0.3},
            evidence={"Shape": "sphere"},
            effects={"ObjVel": {"slow": 0.1, "medium": 0.3, "fast": 0.6}},
        ),
        s.WordProbabilities(header=H, segment_id=2, words={"rolls": 0.4, "the": 1.0}),
        s.Description(
            header=H,
            segment_id=2,
            sentences=[s.ScoredSentence("the robot taps the ball and the ball rolls", -0.5)],
            evidence=s.Evidence(hard={"Shape": "sphere"}, soft={"Action": {"tap": 1.0}}),
        ),
        msgspec.structs.replace(
            health_report("x"), header=_h(s.ServiceHealth), uptime_s=1.0, malformed=3, restarts=2
        ),
        s.StreamEnd(
            header=_h(s.StreamEnd),
            source="demo.mcap",
            messages=12,
            dropped=1,
            last_stamps={"skeleton": 5, "camera": 4},
            damage="demo.mcap is damaged: truncated at byte 9 of 10 (ends inside a record)",
        ),
        s.Ledger(
            header=_h(s.Ledger),
            service="describer",
            instance=1,
            handled={"beyond/robot/language/words": {"words": [(1, 0, 0), (2, 0, 0)]}},
            resume={"gestures": 2, "events": 4},
            resume_stamps={"stamp": 1_700_000_000_123_456_789},  # above 2**53: a time in JSON
        ),
        s.Progress(
            header=H,
            service="objects",
            handled={"beyond/robot/sensors/camera/raw": H.stamp, "beyond/robot/x": -1},
            published={"beyond/robot/vision/objects": 3},
            received={"beyond/robot/gesture/segment": 2},
            published_stamps={"beyond/robot/vision/objects": H.stamp},
        ),
        s.StreamClock(header=H),
        s.AffordanceQuery(
            header=H,
            query=["ObjVel"],
            evidence={"Shape": "circle"},
            soft={"Size": {"small": 0.5, "big": 0.5}},
            gesture={"grasp": 0.1, "tap": 0.8, "touch": 0.1},
        ),
        s.AffordanceAnswer(
            header=H,
            variables=["ObjVel"],
            rows=[s.AnswerRow(assignment={"ObjVel": "fast"}, p=0.7)],
        ),
    ]


def test_every_registered_type_has_an_example() -> None:
    assert {type(m).__name__ for m in examples()} == set(s.REGISTRY)


@pytest.mark.parametrize("message", examples(), ids=lambda m: type(m).__name__)
def test_round_trip_msgpack_and_json(message: s.Message) -> None:
    cls = type(message)
    assert s.decode(s.encode(message), cls, "k") == message
    assert s.from_json(s.to_json(message), cls, "k") == message
    # JSON -> msgpack -> JSON is lossless (what replay of a recording does)
    again = s.decode(s.encode(s.from_json(s.to_json(message), cls)), cls)
    assert s.encode(again) == s.encode(message)


@settings(max_examples=50, deadline=None)
@given(
    st.dictionaries(
        st.text(min_size=1, max_size=12),
        st.tuples(
            st.tuples(*[st.floats(-1e6, 1e6)] * 3),
            st.floats(0, 1),
        ),
        max_size=8,
    ),
    st.integers(0, 2**63 - 1),
)
def test_skeleton_round_trip_any_values(joints: dict, stamp: int) -> None:
    frame = s.SkeletonFrame(
        header=s.Header(version=1, source="h", seq=0, stamp=stamp),
        frame=0,
        joints={k: s.Joint(pos, c) for k, (pos, c) in joints.items()},
    )
    assert s.decode(s.encode(frame), s.SkeletonFrame) == frame
    assert s.from_json(s.to_json(frame), s.SkeletonFrame) == frame


KEY = "beyond/r/sensors/skeleton"


def skeleton_dict(**header: object) -> dict:
    return {
        "type": "SkeletonFrame",
        "header": {"version": 1, "source": "a", "seq": 0, "stamp": 0, **header},
        "frame": 0,
        "joints": {"head": {"position": [0.0, 1.0, 2.0], "confidence": 1.0}},
    }


@pytest.mark.parametrize(
    ("payload", "expected"),
    [
        (b"\xc1\xc1", "malformed"),
        (b"", "truncated"),
        (msgspec.msgpack.encode([1, 2, 3]), "Expected `object`"),
        (msgspec.msgpack.encode({**skeleton_dict(), "type": "CameraFrame"}), "$.type"),
        (msgspec.msgpack.encode(skeleton_dict(version=2)), "schema version 2"),
        (msgspec.msgpack.encode({**skeleton_dict(), "extra": 1}), "unknown field `extra`"),
        (msgspec.msgpack.encode({**skeleton_dict(), "frame": "zero"}), "$.frame"),
        (
            msgspec.msgpack.encode(
                {**skeleton_dict(), "joints": {"h": {"position": [0, 0, 0], "confidence": 2.0}}}
            ),
            "`float` <= 1.0",
        ),
    ],
)
def test_strict_decoding_names_key_and_problem(payload: bytes, expected: str) -> None:
    with pytest.raises(s.SchemaError) as info:
        s.decode(payload, s.SkeletonFrame, KEY)
    text = str(info.value)
    assert isinstance(info.value, InputError)
    assert "\n" not in text
    assert f"SkeletonFrame on {KEY}" in text
    assert expected in text


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), 2e6])
def test_non_finite_or_absurd_positions_are_refused(bad: float) -> None:
    payload = msgspec.msgpack.encode(
        {**skeleton_dict(), "joints": {"h": {"position": [0.0, bad, 0.0], "confidence": 1.0}}}
    )
    with pytest.raises(s.SchemaError, match="position"):
        s.decode(payload, s.SkeletonFrame, KEY)


def test_json_decoding_is_strict_too() -> None:
    with pytest.raises(s.SchemaError, match="schema version 9"):
        s.from_json(json.dumps(skeleton_dict(version=9)), s.SkeletonFrame)


@pytest.mark.parametrize(
    ("make", "problem"),
    [
        (lambda: s.CameraFrame.build(H, 4, 2, b"\x00" * 23), "expected step\\*height = 24"),
        (lambda: s.CameraFrame.build(H, 4, 2, b"\x00" * 24, encoding="yuv"), "encoding 'yuv'"),
        (
            lambda: s.ActionPosterior(
                header=H,
                segment_id=0,
                frame=0,
                actions=["a", "b"],
                posterior=[0.5, 0.6],
                log_likelihood=[0, 0],
                normalised_log_likelihood=[0, 0],
            ),
            "sums to 1.1",
        ),
        (
            lambda: s.GestureSegment(header=H, event="end", segment_id=0, frame=0, start_stamp=0),
            "end_stamp",
        ),
    ],
)
def test_invalid_values_are_refused_on_decode(make, problem: str) -> None:
    # __post_init__ checks run on construction and (as SchemaError) on decoding
    with pytest.raises(ValueError, match=problem):
        make()


def test_camera_frame_is_foxglove_raw_image() -> None:
    schema = s.json_schema(s.CameraFrame)
    assert schema["title"] == "foxglove.RawImage"
    props = schema["properties"]
    for name in ("timestamp", "frame_id", "width", "height", "encoding", "step", "data"):
        assert name in props
    # the byte cap, as base64 characters
    assert props["data"] == {
        "type": "string",
        "contentEncoding": "base64",
        "maxLength": 4 * -(-IMAGE_BYTES_MAX // 3),
    }
    assert props["timestamp"]["properties"].keys() == {"sec", "nsec"}
    frame = s.CameraFrame.build(H, 4, 2, bytes(range(24)))
    as_json = json.loads(s.to_json(frame))
    assert as_json["timestamp"] == {"sec": 1_700_000_000, "nsec": 123_456_789}
    assert as_json["step"] == 12


@pytest.mark.parametrize("cls", list(s.REGISTRY.values()), ids=lambda c: c.__name__)
def test_json_schemas_are_self_contained(cls: type[s.Message]) -> None:
    text = s.json_schema_bytes(cls).decode()
    assert "$ref" not in text and "$defs" not in text
    schema = json.loads(text)
    assert schema["x-beyond-version"] == cls.VERSION
    assert "header" in schema["required"]
    assert s.json_schema_bytes(cls) == s.json_schema_bytes(cls)


def test_registry_and_wire_encoding() -> None:
    assert s.lookup("SkeletonFrame") is s.SkeletonFrame
    assert s.lookup("foxglove.RawImage") is s.CameraFrame
    assert s.type_from_encoding(s.wire_encoding(s.ActionPosterior)) is s.ActionPosterior
    assert s.type_from_encoding("application/json") is None
    with pytest.raises(InputError, match="unknown message type 'Nope'"):
        s.lookup("Nope")
    assert s.versions()["SkeletonFrame"] == 1


def test_keys_are_prefixed_by_robot() -> None:
    keys = s.Keys("icub")
    assert keys.skeleton == "beyond/icub/sensors/skeleton"
    assert keys.gesture_posterior == "beyond/icub/gesture/posterior"
    assert keys.alive("segmenter") == "beyond/icub/alive/segmenter"
    assert keys.health() == "beyond/icub/health/*"
    assert s.type_for_key("beyond/other/sensors/camera/raw") is s.CameraFrame
    assert s.type_for_key("beyond/other/health/x") is s.ServiceHealth
    assert s.type_for_key("elsewhere/sensors/skeleton") is None
    assert s.with_robot("beyond/a/vision/objects", "b") == "beyond/b/vision/objects"
    with pytest.raises(InputError, match="invalid robot name"):
        s.Keys("bad/name")
    with pytest.raises(InputError, match="invalid service name"):
        keys.alive("a*")


@pytest.mark.parametrize("cls", list(s.REGISTRY.values()), ids=lambda c: c.__name__)
def test_every_json_schema_is_exact_in_javascript(cls: type[s.Message]) -> None:
    """The JSON form (recordings, the Foxglove bridge, `beyond echo --json`, `schemas export`'s
    recording/ folder) allows no integer a double would round; on the bus (msgpack) the only
    integers beyond 2^53 are the stamps, each marked as one."""
    assert list(unbounded_integers(codec.recording_json_schema(cls))) == []
    bus = codec.json_schema(cls)
    for where in unbounded_integers(bus):
        node = bus
        for part in where.removeprefix("$.").replace("[", ".").replace("]", "").split("."):
            node = node[int(part)] if isinstance(node, list) else node[part]
        assert STAMP_MARK in node, f"{cls.__name__}: {where} is no stamp, and is unbounded"


@pytest.mark.parametrize("message", examples(), ids=lambda m: type(m).__name__)
def test_json_form_round_trip_with_every_stamp_a_time(message: s.Message) -> None:
    cls = type(message)
    text = codec.to_recording_json(message)
    obj = json.loads(text)
    assert list(unsafe_integers(obj)) == []
    jsonschema.validate(obj, codec.recording_json_schema(cls))
    assert obj["header"]["stamp"] == {"sec": H.stamp // 10**9, "nsec": H.stamp % 10**9}
    assert codec.from_recording_json(text, cls, "k") == message


def test_nested_stamps_are_times_and_none_yet_is_null() -> None:
    progress = next(m for m in examples() if isinstance(m, s.Progress))
    obj = json.loads(codec.to_recording_json(progress))
    assert obj["handled"]["beyond/robot/x"] is None
    assert obj["published_stamps"]["beyond/robot/vision/objects"]["nsec"] == 123_456_789
    assert obj["published"] == {"beyond/robot/vision/objects": 3}  # counts stay numbers
    end = next(m for m in examples() if isinstance(m, s.StreamEnd))
    assert json.loads(codec.to_recording_json(end))["last_stamps"]["skeleton"] == {
        "sec": 0,
        "nsec": 5,
    }
    assert codec.stamp_paths(s.GestureSegment) == ["header.stamp", "start_stamp", "end_stamp"]
    with pytest.raises(s.SchemaError, match="start_stamp"):  # form 3: a time, not a number
        bad = {**json.loads(codec.to_recording_json(examples()[5])), "start_stamp": 1}
        codec.from_recording_json(json.dumps(bad), s.GestureSegment, "k")


def test_a_form_2_file_reads_with_stamps_as_numbers_or_times() -> None:
    """Form 2 wrote header.stamp and the top-level stamps as times, except those typed with
    bounds (GestureSegment's, for a while): both read."""
    segment = next(m for m in examples() if isinstance(m, s.GestureSegment))
    obj = json.loads(s.to_json(segment))
    obj["header"]["stamp"] = {"sec": H.stamp // 10**9, "nsec": H.stamp % 10**9}
    assert codec.from_recording_json(json.dumps(obj), s.GestureSegment, "k", form=2) == segment
