"""Subcommands of the `farm` command line, one module each, and the error of a command-line argument."""
from species.errors import TreefarmError

__all__ = ["CommandLineError"]


class CommandLineError(TreefarmError):
    """A command-line argument is missing, unknown or out of range; the message names it and what is allowed."""
