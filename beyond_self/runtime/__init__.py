"""What every service shares: Zenoh session and config, typed pub/sub, service lifecycle, MCAP
recording and replay, and the clock (wall time live, recording time on replay)."""
