"""One module per `beyond` command (see `beyond.cli.COMMANDS`)."""
