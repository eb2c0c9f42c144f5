"""Decoding one MCAP chunk quickly: decompressed, CRC-checked, messages parsed straight from
the buffer (the damage-tolerant reader in runtime.recording.reader calls it for every chunk)."""

from __future__ import annotations

import io
import struct
from typing import Any

from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Schema
from mcap.records import Message as McapMessage
from mcap.stream_reader import get_chunk_data_stream

from beyond_self.core.errors import InputError

_RECORD_HEAD = struct.Struct("<BQ")  # opcode, body length
_MESSAGE_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time


def _chunk_data(chunk: Chunk) -> bytes:
    """The chunk's records, decompressed (by mcap, which brings its codecs) and checked against
    its CRC."""
    if chunk.compression not in ("zstd", "lz4", ""):
        raise InputError(f"unsupported chunk compression {chunk.compression!r}")
    stream, length = get_chunk_data_stream(chunk, validate_crc=True)
    data: bytes = stream.read(length)
    return data


def chunk_records(chunk: Chunk) -> list[Any]:
    """Schema, channel and message records of a chunk (what mcap's `breakup_chunk` returns),
    with messages parsed straight from the buffer: mcap's general stream reader spends more
    time per camera frame than the CRC check."""
    data = _chunk_data(chunk)
    records: list[Any] = []
    pos, end = 0, len(data)
    while pos < end:
        if end - pos < _RECORD_HEAD.size:
            raise EndOfFile()
        opcode, length = _RECORD_HEAD.unpack_from(data, pos)
        start = pos + _RECORD_HEAD.size
        pos = start + length
        if pos > end:
            raise EndOfFile()
        if opcode == Opcode.MESSAGE:
            if length < _MESSAGE_HEAD.size:
                raise EndOfFile()
            channel_id, sequence, log_time, publish_time = _MESSAGE_HEAD.unpack_from(data, start)
            records.append(
                McapMessage(
                    channel_id=channel_id,
                    sequence=sequence,
                    log_time=log_time,
                    publish_time=publish_time,
                    data=data[start + _MESSAGE_HEAD.size : pos],
                )
            )
        elif opcode in (Opcode.CHANNEL, Opcode.SCHEMA):
            stream = ReadDataStream(io.BytesIO(data[start:pos]))
            records.append((Channel if opcode == Opcode.CHANNEL else Schema).read(stream))
    return records
