"""What makes a service survive crashes: exactly-once ledgers, snapshots, where a restored
service resumes, the state folder and a run's state, the source log."""
