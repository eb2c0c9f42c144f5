"""One module per `beyond` command (see `beyond_self.cli.COMMANDS`)."""
