"""The header every bus message carries and the base class that makes decoding strict.

Why a tagged, frozen, closed Struct: a payload is checked for its type name (the `type` tag), for
fields nobody declared (`forbid_unknown_fields`) and, after decoding, for its schema version, so a
sender on another version or a message on the wrong key is refused instead of half-understood.
"""

from __future__ import annotations

from typing import Annotated, ClassVar

import msgspec

# Bounds checked by msgspec's C decoder as a payload is decoded (cheap: no Python per field).
NAME_MAX = 256  # characters of a name, label, key or id string
STAMP_MAX = 2**63 - 1  # nanoseconds since the epoch: int64, never negative
# Counts and sequence numbers: exact as JSON numbers in JavaScript (doubles). Stamps go above it,
# which is why every JSON form writes them as a Foxglove Time (schemas.codec).
JS_INT_MAX = 2**53 - 1
# A stamp, in nanoseconds since the Unix epoch: the mark tells the JSON form (schemas.codec) to
# write it as a Foxglove Time {sec, nsec}; on the wire (msgpack) it is a 64-bit integer.
STAMP_MARK = "x-beyond-stamp"
Stamp = Annotated[
    int, msgspec.Meta(ge=0, le=STAMP_MAX, extra_json_schema={STAMP_MARK: "ns since the epoch"})
]


class Header(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Who sent a message, in what order, about which instant, and which input it answers.

    stamp: nanoseconds since the Unix epoch, of the data (sensor time live, recording time on
    replay), not of sending. A derived message copies the stamp of the input it derives from, so
    replaying a recording gives byte-identical outputs.
    correlation: ties an output to the input it came from ("<source>/<seq>" of the first message
    in a chain, copied along the chain).
    """

    version: Annotated[int, msgspec.Meta(ge=0, le=1_000_000)]
    source: Annotated[str, msgspec.Meta(max_length=NAME_MAX)]
    seq: Annotated[int, msgspec.Meta(ge=0, le=JS_INT_MAX)]
    stamp: Stamp
    correlation: Annotated[str, msgspec.Meta(max_length=2 * NAME_MAX)] = ""


class Message(
    msgspec.Struct,
    frozen=True,
    kw_only=True,
    forbid_unknown_fields=True,
    tag_field="type",
    tag=True,
):
    """Base of every bus message; subclasses set VERSION and bump it on any incompatible change."""

    VERSION: ClassVar[int] = 1
    # Name of the MCAP schema record (Foxglove recognises some well-known names).
    SCHEMA_NAME: ClassVar[str] = ""

    header: Header

    @classmethod
    def type_name(cls) -> str:
        return cls.__name__

    @classmethod
    def original_header(cls, source: str, seq: int, stamp: int, chain: str = "") -> Header:
        """The header of a message that starts a chain (a sensor's, a health report): numbered
        by its source, and its own correlation ("<source>[/<chain>]/<seq>"), which derived
        messages copy along."""
        correlation = f"{source}/{chain}/{seq}" if chain else f"{source}/{seq}"
        return Header(
            version=cls.VERSION, source=source, seq=seq, stamp=stamp, correlation=correlation
        )

    @classmethod
    def schema_name(cls) -> str:
        return cls.SCHEMA_NAME or f"beyond.{cls.__name__}"
