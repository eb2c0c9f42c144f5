from beyond_self.cli import entry

raise SystemExit(entry())
