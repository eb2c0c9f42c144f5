"""Wire encoding (msgpack), JSON form, JSON Schema export and the registry of message types.

Decoding is strict and always ends in either a valid, current-version message or a
`SchemaError` (an `InputError`) whose one-line message names the key, the type and what was wrong.
Services catch it, count it and keep running.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any, TypeVar

import msgspec

from beyond_self.core.errors import InputError, unknown
from beyond_self.schemas.base import STAMP_MARK, STAMP_MAX, Message
from beyond_self.schemas.messages import ALL_MESSAGES

M = TypeVar("M", bound=Message)

WIRE_MIME = "application/msgpack"

# type name -> type. One table: recordings, `beyond echo` and the recorder resolve types here.
REGISTRY: dict[str, type[Message]] = {cls.type_name(): cls for cls in ALL_MESSAGES}
_BY_SCHEMA_NAME: dict[str, type[Message]] = {cls.schema_name(): cls for cls in ALL_MESSAGES}


class SchemaError(InputError):
    """A payload that is not a valid message of the expected type and version."""


def lookup(name: str) -> type[Message]:
    """The message type called `name` (type name like "SkeletonFrame" or schema name like
    "beyond.SkeletonFrame" / "foxglove.RawImage")."""
    cls = REGISTRY.get(name) or _BY_SCHEMA_NAME.get(name)
    if cls is None:
        raise unknown("message type", name, sorted(REGISTRY))
    return cls


def versions() -> dict[str, int]:
    """Every registered type with its current schema version."""
    return {name: cls.VERSION for name, cls in REGISTRY.items()}


def wire_encoding(cls: type[Message]) -> str:
    """The Zenoh encoding string sent with each sample: mime type plus "<Type>/v<version>", so a
    generic tool (recorder, echo) can decode any key without a table."""
    return f"{WIRE_MIME};{cls.type_name()}/v{cls.VERSION}"


def type_from_encoding(encoding: str) -> type[Message] | None:
    """The message type named by a wire encoding string, if it is one of ours."""
    mime, _, schema = encoding.partition(";")
    if mime != WIRE_MIME or "/v" not in schema:
        return None
    return REGISTRY.get(schema.rsplit("/v", 1)[0])


_encoder = msgspec.msgpack.Encoder()
_json_encoder = msgspec.json.Encoder()


class _Decoders(dict[type[Message], Any]):
    """Strict decoders by message type, made on first use (`make` is msgspec's Decoder class)."""

    def __init__(self, make: Callable[[type[Message]], Any]) -> None:
        super().__init__()
        self.make = make

    def __missing__(self, cls: type[Message]) -> Any:
        decoder = self[cls] = self.make(cls)
        return decoder


_msgpack_decoders = _Decoders(msgspec.msgpack.Decoder)
_json_decoders = _Decoders(msgspec.json.Decoder)


def encode(message: Message) -> bytes:
    """msgpack bytes of a message (deterministic: same message, same bytes)."""
    return _encoder.encode(message)


def encode_into(message: Message, buffer: bytearray) -> None:
    """msgpack of a message written into `buffer` (resized to fit; same bytes as `encode`).

    For publishers that send many large messages: reusing one buffer avoids allocating (and,
    with glibc, page-faulting in) a fresh block for every camera frame, which costs more than
    the encoding itself."""
    _encoder.encode_into(message, buffer)


def to_json(message: Message) -> bytes:
    """JSON bytes of a message (bytes fields as base64, as JSON Schema / Foxglove expect)."""
    return _json_encoder.encode(message)


def _where(key: str, cls: type[Message]) -> str:
    return f"{cls.type_name()} on {key}" if key else cls.type_name()


def _version_problem(raw: object, cls: type[Message]) -> str | None:
    if isinstance(raw, dict):
        header = raw.get("header")
        if isinstance(header, dict) and "version" in header:
            got = header["version"]
            if got != cls.VERSION:
                return f"schema version {got!r}, this build reads version {cls.VERSION}"
    return None


def _check(message: M, cls: type[M], key: str) -> M:
    if message.header.version != cls.VERSION:
        raise SchemaError(
            f"bad {_where(key, cls)}: schema version {message.header.version}, "
            f"this build reads version {cls.VERSION}"
        )
    return message


def _schema_error(
    cls: type[Message], key: str, exc: Exception, raw: Callable[[], object]
) -> SchemaError:
    """The one-line error for a payload that did not decode as `cls`: an old schema version is
    named as such, found by reading the payload loosely again (`raw`), only once it has failed."""
    try:
        problem = _version_problem(raw(), cls)
    except msgspec.DecodeError:
        problem = None
    return SchemaError(f"bad {_where(key, cls)}: {problem or exc}")


def decode(data: bytes | bytearray | memoryview, cls: type[M], key: str = "") -> M:
    """Strictly decode msgpack bytes as `cls`; SchemaError names the key and what was wrong."""
    try:
        message: M = _msgpack_decoders[cls].decode(data)
    except msgspec.DecodeError as exc:
        raise _schema_error(cls, key, exc, lambda: msgspec.msgpack.decode(data)) from None
    return _check(message, cls, key)


def from_json(data: bytes | str, cls: type[M], key: str = "") -> M:
    """Strictly decode JSON as `cls` (the form stored in recordings)."""
    try:
        message: M = _json_decoders[cls].decode(data)
    except msgspec.DecodeError as exc:
        raise _schema_error(cls, key, exc, lambda: msgspec.json.decode(data)) from None
    return _check(message, cls, key)


def from_object(obj: Any, cls: type[M], key: str = "") -> M:
    """Strictly convert decoded JSON (dicts, lists, numbers) to `cls`, as `from_json` would;
    for a message typed in by hand (`beyond pub`)."""
    try:
        message: M = msgspec.convert(obj, cls)
    except msgspec.ValidationError as exc:
        raise _schema_error(cls, key, exc, lambda: obj) from None
    return _check(message, cls, key)


def _inline(node: Any, defs: dict[str, Any]) -> Any:
    if isinstance(node, dict):
        ref = node.get("$ref")
        if isinstance(ref, str) and ref.startswith("#/$defs/"):
            target = copy.deepcopy(defs[ref.removeprefix("#/$defs/")])
            rest = {k: v for k, v in node.items() if k != "$ref"}
            return _inline({**target, **rest}, defs)
        return {k: _inline(v, defs) for k, v in node.items()}
    if isinstance(node, list):
        return [_inline(v, defs) for v in node]
    return node


def self_contained_schema(cls: type[Any]) -> dict[str, Any]:
    """msgspec's JSON Schema of any Struct type with its `$ref`s inlined."""
    raw = msgspec.json.schema(cls)
    schema: dict[str, Any] = _inline(raw, raw.get("$defs", {}))
    schema.pop("$defs", None)
    return schema


def json_schema(cls: type[Message]) -> dict[str, Any]:
    """Self-contained JSON Schema (draft 2020-12) of a message type, `$ref`s inlined because
    some viewers (Foxglove) do not follow them. Our types are not recursive."""
    schema = self_contained_schema(cls)
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = cls.schema_name()
    schema["description"] = (cls.__doc__ or "").strip().split("\n\n")[0].replace("\n", " ")
    schema["x-beyond-type"] = cls.type_name()
    schema["x-beyond-version"] = cls.VERSION
    return schema


def json_schema_bytes(cls: type[Message]) -> bytes:
    """The JSON Schema as canonical bytes (sorted keys), identical across runs."""
    return msgspec.json.encode(json_schema(cls), order="sorted")


# --- The JSON form: recordings, the Foxglove bridge, `beyond echo --json` ----------------------
#
# Form 1 (files written before it had a number) is `to_json`: stamps are JSON integers of
# nanoseconds, above 2**53, which every JavaScript reader (Foxglove included) rounds. Form 2
# wrote `header.stamp` and the top-level `*_stamp` fields as Foxglove's `Time` {"sec", "nsec"}
# (for a while only those typed plain `int`, so a form-2 file may hold either). Form 3 writes
# every stamp as a `Time`, wherever it is: every field typed `base.Stamp` (marked in the schema),
# in a struct, an optional, a list or a dict's values (`StreamEnd.last_stamps`,
# `Progress.handled`), and a "none yet" stamp (-1) as null; every other integer is within
# 2**53 (`base.JS_INT_MAX`), so every number a JSON reader sees is exact. The bus wire format
# (msgpack) and the Structs are unchanged; each recorded channel names its form in its metadata,
# so older files read.

RECORDING_JSON_FORM = 3
RECORDING_JSON_FORMS = (1, 2, 3)
_TIME_SCHEMA: dict[str, Any] = {
    "title": "time",
    "description": "Foxglove Time: seconds and nanoseconds since the Unix epoch",
    "type": "object",
    "properties": {
        "sec": {"type": "integer", "minimum": 0, "maximum": STAMP_MAX // 1_000_000_000},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
    },
    "required": ["sec", "nsec"],
    "additionalProperties": False,
}
_STAMP = "stamp"
_STAMP_OR_NONE = "stamp or none"  # -1 on the wire, null in JSON
# Where the stamps of a type are: a leaf (_STAMP, _STAMP_OR_NONE), a struct's fields by name,
# ("values", plan) of a dict or ("items", plan) of a list or tuple.
Plan = str | dict[str, "Plan"] | tuple[str, "Plan"]
_PLANS: dict[type[Message], Plan] = {}


def _plan(info: msgspec.inspect.Type) -> Plan | None:
    """Where the stamps are in a value of type `info` (None: nowhere)."""
    mi = msgspec.inspect
    if isinstance(info, mi.Metadata):
        if isinstance(info.type, mi.IntType) and STAMP_MARK in (info.extra_json_schema or {}):
            ge = info.type.ge
            return _STAMP_OR_NONE if ge is not None and ge < 0 else _STAMP
        return _plan(info.type)
    if isinstance(info, mi.StructType):
        fields = {f.encode_name: p for f in info.fields if (p := _plan(f.type)) is not None}
        return fields or None
    if isinstance(info, mi.DictType):
        inner = _plan(info.value_type)
        return None if inner is None else ("values", inner)
    if isinstance(info, mi.ListType | mi.VarTupleType):
        inner = _plan(info.item_type)
        return None if inner is None else ("items", inner)
    if isinstance(info, mi.UnionType):  # an optional: the plan of its one non-null member
        plans = [p for t in info.types if (p := _plan(t)) is not None]
        return plans[0] if plans else None
    return None


def stamp_plan(cls: type[Message]) -> Plan:
    """Where `cls` holds stamps (header.stamp at least), for the JSON form."""
    plan = _PLANS.get(cls)
    if plan is None:
        found = _plan(msgspec.inspect.type_info(cls))
        assert isinstance(found, dict)  # every message has header.stamp
        plan = _PLANS[cls] = found
    return plan


def stamp_paths(cls: type[Message]) -> list[str]:
    """The stamps of `cls` as paths (`header.stamp`, `start_stamp`, `last_stamps.*`)."""

    def paths(plan: Plan, prefix: str) -> list[str]:
        if isinstance(plan, str):
            return [prefix]
        if isinstance(plan, dict):
            return [p for k, sub in plan.items() for p in paths(sub, f"{prefix}.{k}")]
        return paths(plan[1], f"{prefix}.*" if plan[0] == "values" else f"{prefix}[]")

    found = [p.removeprefix(".") for p in paths(stamp_plan(cls), "")]
    return sorted(found, key=lambda p: not p.startswith("header."))  # header.stamp first


def shift_stamps(message: M, offset: int, **also: Any) -> M:
    """`message` with every stamp it holds (header.stamp and every field typed `base.Stamp`,
    wherever it is) `offset` ns later; a "none yet" stamp (-1) stays none. How a looped replay
    moves a pass later without missing a stamp nested in a dict or a list. `also`: other fields
    to change at once (a field that must agree with the stamps: a camera frame's timestamp)."""
    if offset == 0 and not also:
        return message
    plan = stamp_plan(type(message))
    assert isinstance(plan, dict)  # a message is a struct
    changes = {name: _shift(getattr(message, name), sub, offset) for name, sub in plan.items()}
    return msgspec.structs.replace(message, **changes, **also)


def _shift(value: Any, plan: Plan, offset: int) -> Any:
    if value is None:
        return None
    if isinstance(plan, str):
        return value + offset if value >= 0 else value
    if isinstance(plan, dict):
        changes = {name: _shift(getattr(value, name), sub, offset) for name, sub in plan.items()}
        return msgspec.structs.replace(value, **changes)
    kind, sub = plan
    if kind == "values":
        return {k: _shift(v, sub, offset) for k, v in value.items()}
    return type(value)(_shift(v, sub, offset) for v in value)


def _to_form(value: Any, plan: Plan) -> Any:
    if value is None:
        return None
    if isinstance(plan, str):
        if value < 0:  # only a stamp-or-none may be negative (-1), as the bounds say
            return None
        return {"sec": value // 1_000_000_000, "nsec": value % 1_000_000_000}
    if isinstance(plan, dict):
        for name, sub in plan.items():
            if name in value:
                value[name] = _to_form(value[name], sub)
        return value
    kind, sub = plan
    if kind == "values":
        return {k: _to_form(v, sub) for k, v in value.items()}
    return [_to_form(v, sub) for v in value]


def _from_time(value: Any, where: str) -> int:
    if (
        isinstance(value, dict)
        and set(value) == {"sec", "nsec"}
        and all(type(v) is int for v in value.values())
        and value["sec"] >= 0
        and 0 <= value["nsec"] < 1_000_000_000
    ):
        return int(value["sec"]) * 1_000_000_000 + int(value["nsec"])
    raise ValueError(f"{where} is {value!r}, expected a time {{sec, nsec}}")


def _from_form(value: Any, plan: Plan, where: str, form: int) -> Any:
    """The inverse of `_to_form`; form 2 (header.stamp and top-level fields only, as a time or
    an integer) is read too."""
    if isinstance(plan, str):
        if value is None:
            return -1 if plan == _STAMP_OR_NONE else None
        if form == 2 and type(value) is int:
            return value
        return _from_time(value, where)
    if not isinstance(value, dict | list):
        return value  # the wrong shape: msgspec says what was expected
    if isinstance(plan, dict):
        if isinstance(value, dict):
            for name, sub in plan.items():
                if name in value and (form == 3 or isinstance(sub, str) or name == "header"):
                    value[name] = _from_form(value[name], sub, f"{where}{name}.", form)
        return value
    kind, sub = plan
    if kind == "values" and isinstance(value, dict):
        return {k: _from_form(v, sub, f"{where}{k}.", form) for k, v in value.items()}
    if kind == "items" and isinstance(value, list):
        return [_from_form(v, sub, f"{where}[{i}].", form) for i, v in enumerate(value)]
    return value


def to_recording_json(message: Message) -> bytes:
    """JSON of `message` in the current form (every stamp a {sec, nsec}): what recordings, the
    Foxglove bridge and `beyond echo --json` write."""
    obj = msgspec.to_builtins(message, builtin_types=(bytes,))
    return _json_encoder.encode(_to_form(obj, stamp_plan(type(message))))


def from_recording_object(
    obj: Any, cls: type[M], key: str = "", form: int = RECORDING_JSON_FORM
) -> M:
    """Strictly convert a decoded JSON object in form 2 or 3 to `cls` (`beyond pub` takes what
    `beyond echo --json` prints)."""
    try:
        if not isinstance(obj, dict):
            raise ValueError("expected a JSON object")
        problem = _version_problem(obj, cls)
        if problem:
            raise ValueError(problem)
        obj = _from_form(obj, stamp_plan(cls), "", form)
        message: M = msgspec.convert(obj, cls)
    except (msgspec.ValidationError, ValueError) as exc:
        raise SchemaError(f"bad {_where(key, cls)}: {exc}") from None
    return _check(message, cls, key)


def from_recording_json(
    data: bytes | str, cls: type[M], key: str = "", form: int = RECORDING_JSON_FORM
) -> M:
    """Strictly decode a recorded message stored in JSON form `form` (1, 2 or 3)."""
    if form == 1:
        return from_json(data, cls, key)
    if form not in RECORDING_JSON_FORMS:
        raise SchemaError(
            f"bad {_where(key, cls)}: recording JSON form {form}, this build reads "
            f"{', '.join(map(str, RECORDING_JSON_FORMS))}"
        )
    try:
        obj = msgspec.json.decode(data)
    except msgspec.DecodeError as exc:
        raise SchemaError(f"bad {_where(key, cls)}: {exc}") from None
    return from_recording_object(obj, cls, key, form)


def _schema_form(node: dict[str, Any], plan: Plan) -> dict[str, Any]:
    if "anyOf" in node:  # an optional: its non-null member
        node["anyOf"] = [
            m if m.get("type") == "null" else _schema_form(m, plan) for m in node["anyOf"]
        ]
        return node
    if isinstance(plan, str):
        time = {**_TIME_SCHEMA, **({"default": node["default"]} if "default" in node else {})}
        if plan == _STAMP_OR_NONE:
            return {"anyOf": [time, {"type": "null", "description": "none yet"}]}
        return time
    if isinstance(plan, dict):
        props = node["properties"]
        for name, sub in plan.items():
            props[name] = _schema_form(props[name], sub)
        return node
    kind, sub = plan
    where = "additionalProperties" if kind == "values" else "items"
    node[where] = _schema_form(node[where], sub)
    return node


def recording_json_schema(cls: type[Message]) -> dict[str, Any]:
    """JSON Schema of `cls` in the current JSON form: `json_schema` with every stamp a
    {sec, nsec} object. This is what a recording's channel and the Foxglove bridge declare."""
    schema = _schema_form(json_schema(cls), stamp_plan(cls))
    schema["x-beyond-recording-form"] = RECORDING_JSON_FORM
    return schema


def recording_json_schema_bytes(cls: type[Message]) -> bytes:
    """`recording_json_schema` as canonical bytes (sorted keys), identical across runs."""
    return msgspec.json.encode(recording_json_schema(cls), order="sorted")
