"""The Zenoh session and everything said on it: configuration, typed publish/subscribe,
queries, presence."""
