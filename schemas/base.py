"""The header every bus message carries and the base class that makes decoding strict.

Why a tagged, frozen, closed Struct: a payload is checked for its type name (the `type` tag), for
fields nobody declared (`forbid_unknown_fields`) and, after decoding, for its schema version, so a
sender on another version or a message on the wrong key is refused instead of half-understood.
"""

from __future__ import annotations

from typing import ClassVar

import msgspec


class Header(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Who sent a message, in what order, about which instant, and which input it answers.

    stamp: nanoseconds since the Unix epoch, of the data (sensor time live, recording time on
    replay), not of sending. A derived message copies the stamp of the input it derives from, so
    replaying a recording gives byte-identical outputs.
    correlation: ties an output to the input it came from ("<source>/<seq>" of the first message
    in a chain, copied along the chain).
    """

    version: int
    source: str
    seq: int
    stamp: int
    correlation: str = ""


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
    def schema_name(cls) -> str:
        return cls.SCHEMA_NAME or f"beyond.{cls.__name__}"
