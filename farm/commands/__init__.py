"""Subcommands of the `farm` command line, one module each."""
