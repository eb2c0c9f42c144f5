"""What makes a service survive crashes: exactly-once ledgers, snapshots, the source log,
recovery from caches, processes bound to their supervisor, error accounting."""
