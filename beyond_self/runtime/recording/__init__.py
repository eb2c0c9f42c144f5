"""MCAP recordings: reading, writing, recording the bus, replaying it."""
