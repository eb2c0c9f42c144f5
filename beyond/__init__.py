"""The `beyond` command-line front end: one dispatcher, one module per command group."""
