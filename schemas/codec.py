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
from beyond_self.schemas.base import Message
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


# --- The JSON form stored in recordings ------------------------------------------------------
#
# Form 1 (files written before it had a number) is `to_json`: stamps are JSON integers of
# nanoseconds, above 2**53, which every JavaScript reader (Foxglove included) rounds. Form 2
# writes every stamp (`header.stamp` and the top-level `*_stamp` fields) as Foxglove's `Time`
# {"sec", "nsec"}, which any reader keeps exact. The bus wire format (msgpack) and the Structs
# are unchanged; only recordings carry the form, in each channel's metadata, so older files read.

RECORDING_JSON_FORM = 2
RECORDING_JSON_FORMS = (1, 2)
_STAMP_FIELDS: dict[type[Message], tuple[str, ...]] = {}
_TIME_SCHEMA: dict[str, Any] = {
    "title": "time",
    "description": "Foxglove Time: seconds and nanoseconds since the Unix epoch",
    "type": "object",
    "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
    },
    "required": ["sec", "nsec"],
    "additionalProperties": False,
}


def stamp_fields(cls: type[Message]) -> tuple[str, ...]:
    """Top-level fields of `cls` holding a nanosecond stamp (besides `header.stamp`)."""
    names = _STAMP_FIELDS.get(cls)
    if names is None:
        names = _STAMP_FIELDS[cls] = tuple(
            f.name
            for f in msgspec.structs.fields(cls)
            if f.name.endswith("_stamp") and f.type in (int, int | None)
        )
    return names


def _to_time(ns: int) -> dict[str, int]:
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


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


def to_recording_json(message: Message) -> bytes:
    """JSON of `message` in the current recording form (stamps as {sec, nsec})."""
    obj: dict[str, Any] = msgspec.to_builtins(message, builtin_types=(bytes,))
    header = obj["header"]
    header["stamp"] = _to_time(header["stamp"])
    for name in stamp_fields(type(message)):
        if obj.get(name) is not None:
            obj[name] = _to_time(obj[name])
    return _json_encoder.encode(obj)


def from_recording_json(
    data: bytes | str, cls: type[M], key: str = "", form: int = RECORDING_JSON_FORM
) -> M:
    """Strictly decode a recorded message stored in JSON form `form` (1 or 2)."""
    if form == 1:
        return from_json(data, cls, key)
    if form != RECORDING_JSON_FORM:
        raise SchemaError(
            f"bad {_where(key, cls)}: recording JSON form {form}, this build reads "
            f"{', '.join(map(str, RECORDING_JSON_FORMS))}"
        )
    try:
        obj = msgspec.json.decode(data)
        if not isinstance(obj, dict) or not isinstance(obj.get("header"), dict):
            raise ValueError("expected an object with a header")
        problem = _version_problem(obj, cls)
        if problem:
            raise ValueError(problem)
        header = obj["header"]
        if "stamp" in header:
            header["stamp"] = _from_time(header["stamp"], "header.stamp")
        for name in stamp_fields(cls):
            if obj.get(name) is not None:
                obj[name] = _from_time(obj[name], name)
        message: M = msgspec.convert(obj, cls)
    except (msgspec.DecodeError, msgspec.ValidationError, ValueError) as exc:
        raise SchemaError(f"bad {_where(key, cls)}: {exc}") from None
    return _check(message, cls, key)


def recording_json_schema(cls: type[Message]) -> dict[str, Any]:
    """JSON Schema of `cls` in the current recording form: `json_schema` with every stamp a
    {sec, nsec} object. This is what a recording's channel declares."""
    schema = json_schema(cls)
    props = schema["properties"]
    props["header"]["properties"]["stamp"] = dict(_TIME_SCHEMA)
    for name in stamp_fields(cls):
        old = props[name]
        time = dict(_TIME_SCHEMA)
        props[name] = {"anyOf": [time, {"type": "null"}]} if "anyOf" in old else time
        if "default" in old:
            props[name]["default"] = old["default"]
    schema["x-beyond-recording-form"] = RECORDING_JSON_FORM
    return schema


def recording_json_schema_bytes(cls: type[Message]) -> bytes:
    """`recording_json_schema` as canonical bytes (sorted keys), identical across runs."""
    return msgspec.json.encode(recording_json_schema(cls), order="sorted")
