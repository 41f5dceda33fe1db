"""Subcommands of the `farm` command line, one module each, and the error of a command-line argument."""
from species.errors import TreefarmError

__all__ = ["CommandLineError", "check_flag_int"]


class CommandLineError(TreefarmError):
    """A command-line argument is missing, unknown or out of range; the message names it and what is allowed."""


def check_flag_int(flag: str, value: int, low: int, high: int | None = None) -> int:
    """`value` of the integer option `flag` when in [low, high] (no upper bound when high is None); else a
    CommandLineError naming the flag, the value and the range. Checked before anything is written.
    The range check is the job spec's (`farm.jobs.check_int`); only the wording is a command line's."""
    from farm.jobs import JobSpecError, check_int  # here: farm.jobs imports renderers (the CLI's start-up time)

    try:
        return check_int(flag, value, low, high)
    except JobSpecError as exc:
        raise CommandLineError(f"{flag} {value} is out of range: allowed {exc.allowed}") from None
