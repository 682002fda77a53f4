"""The operator's console: the `spacearm` command and its subcommands."""
