"""How beyond-self stores bus messages in MCAP: names and format decisions that the writer
(runtime.recording_writer) and the readers (runtime.recording) share.

Format decisions (see runtime/README.md):
- Channel topic = the Zenoh key. Our messages are stored with message encoding "json" and a
  "jsonschema" schema (the msgspec schema, `$ref`s inlined), both well-known MCAP encodings, so
  any MCAP tool decodes them without this project; msgpack, the wire encoding, is converted on
  the way in and back on replay (`RecordedMessage.wire()`), losslessly (floats round-trip
  exactly, bytes as base64, stamps as Foxglove `Time` {sec, nsec} so that a JavaScript reader,
  whose numbers are doubles, keeps them exact). Each channel names its JSON form in its
  metadata (`beyond.json_form`, see `schemas.codec.RECORDING_JSON_FORM`); a channel without it
  is form 1 (stamps as integers), read as before. Camera frames are stored under Foxglove's
  schema names `foxglove.RawImage` / `foxglove.CompressedImage`, whose fields they carry, so
  Foxglove shows them. Samples on keys that are not ours are stored as they came, schemaless,
  with their Zenoh encoding as the message encoding.
- log_time = publish_time = the header stamp (the data's time), so a viewer's timeline, the
  message's own stamp and the camera `timestamp` agree; on a replay every message is on the
  stream's clock (runtime.clock). A sample without a stamp (0: a service on a replay's clock
  before the stream has started) that comes before any stamped one waits for it and is logged
  at its stamp; later, or not ours, at its receive time moved onto the stamps' clock (by the
  offset of the last stamped sample), never before the last message of its channel, never at
  0. A live recorder writes each chunk in log-time order, and what comes since a flush waits
  for the next one, so an output that comes after newer inputs (a gesture's final belief,
  stamped at the gesture's end) is written in its place. A channel's log times never step
  back: one later than that is logged at its channel's last log time, its publish_time and
  contents its own. Replay follows publish_time.
- No attachment index and, without metadata, no metadata index: an empty index group with a
  summary offset pointing at it is an error to `mcap doctor`. The data-section CRC is written.
- Chunked and compressed (zstd); the file is written unbuffered and the open chunk is closed at
  least every `flush_interval` s, so a killed recorder leaves every closed chunk readable.
  The reader (runtime.recording) reads sequentially and stops cleanly at the first damaged record.
- Deterministic: the same messages written through `RecordingWriter` give the same bytes (no
  wall-clock time is stored unless the caller adds it as metadata).
"""

JSON = "json"
JSONSCHEMA = "jsonschema"
META_TYPE = "beyond.type"
META_VERSION = "beyond.version"
META_FORM = "beyond.json_form"
META_VIEW = "beyond.view"  # a derived Foxglove view channel (not replayed)
