"""Wire encoding (msgpack), JSON form, JSON Schema export and the registry of message types.

Decoding is strict and always ends in either a valid, current-version message or a
`SchemaError` (an `InputError`) whose one-line message names the key, the type and what was wrong.
Services catch it, count it and keep running.
"""

from __future__ import annotations

import copy
from typing import Any, TypeVar

import msgspec

from cognition.errors import InputError, unknown
from schemas.base import Message
from schemas.messages import ALL_MESSAGES

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
_msgpack_decoders: dict[type[Message], msgspec.msgpack.Decoder[Any]] = {}
_json_decoders: dict[type[Message], msgspec.json.Decoder[Any]] = {}


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


def decode(data: bytes | bytearray | memoryview, cls: type[M], key: str = "") -> M:
    """Strictly decode msgpack bytes as `cls`; SchemaError names the key and what was wrong."""
    decoder = _msgpack_decoders.get(cls)
    if decoder is None:
        decoder = _msgpack_decoders[cls] = msgspec.msgpack.Decoder(cls)
    try:
        message: M = decoder.decode(data)
    except msgspec.DecodeError as exc:
        try:
            problem = _version_problem(msgspec.msgpack.decode(data), cls)
        except msgspec.DecodeError:
            problem = None
        raise SchemaError(f"bad {_where(key, cls)}: {problem or exc}") from None
    return _check(message, cls, key)


def from_json(data: bytes | str, cls: type[M], key: str = "") -> M:
    """Strictly decode JSON as `cls` (the form stored in recordings)."""
    decoder = _json_decoders.get(cls)
    if decoder is None:
        decoder = _json_decoders[cls] = msgspec.json.Decoder(cls)
    try:
        message: M = decoder.decode(data)
    except msgspec.DecodeError as exc:
        try:
            problem = _version_problem(msgspec.json.decode(data), cls)
        except msgspec.DecodeError:
            problem = None
        raise SchemaError(f"bad {_where(key, cls)}: {problem or exc}") from None
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


def json_schema(cls: type[Message]) -> dict[str, Any]:
    """Self-contained JSON Schema (draft 2020-12) of a message type, `$ref`s inlined because
    some viewers (Foxglove) do not follow them. Our types are not recursive."""
    raw = msgspec.json.schema(cls)
    schema: dict[str, Any] = _inline(raw, raw.get("$defs", {}))
    schema.pop("$defs", None)
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = cls.schema_name()
    schema["description"] = (cls.__doc__ or "").strip().split("\n\n")[0].replace("\n", " ")
    schema["x-beyond-type"] = cls.type_name()
    schema["x-beyond-version"] = cls.VERSION
    return schema


def json_schema_bytes(cls: type[Message]) -> bytes:
    """The JSON Schema as canonical bytes (sorted keys), identical across runs."""
    return msgspec.json.encode(json_schema(cls), order="sorted")
