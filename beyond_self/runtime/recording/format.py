"""How beyond-self stores bus messages in MCAP: the names the writer (runtime.recording.writer)
and the readers (runtime.recording.reader) share.

Topic = the Zenoh key. Our messages are JSON with a JSON Schema (MCAP's well-known encodings) so
any MCAP tool decodes them without this project; msgpack, the wire encoding, is converted both
ways losslessly, and every stamp is a Foxglove `Time`, exact for a JavaScript reader. Each
channel names its JSON form in its metadata (META_FORM). log_time = publish_time = the header
stamp, so a viewer's timeline and the messages' own stamps agree; replay follows publish_time.
The rest (chunks, unstamped samples, determinism): docs/how-to/recordings.md.
"""

JSON = "json"
JSONSCHEMA = "jsonschema"
META_TYPE = "beyond.type"
META_VERSION = "beyond.version"
META_FORM = "beyond.json_form"
META_VIEW = "beyond.view"  # a derived Foxglove view channel (not replayed)
