"""The `farm` command line: one subcommand module per job in `farm/commands/`.

Errors a user can act on (`TreefarmError`, and file errors of paths named on the command line) are printed as one
line (`farm: error: ...`) with exit status 2; anything else is a bug: its traceback, a line asking to report it,
and exit status 1. `farm --debug COMMAND` prints the traceback of a user error too. Statuses: docs/cli.md.
"""
from __future__ import annotations

import argparse
import gc
import importlib
import os
import sys
import traceback

# OpenBLAS (numpy and scipy load a copy each) starts a thread per core as it loads, and its threads spin while they
# wait: CPU time that `farm reconstruct`, whose matrix products are too small to share out, would pay at start-up
# and after each product. One thread there, unless the user set a number; set before numpy's first import (through
# species below), as OpenBLAS reads it only when it loads.
if next((word for word in sys.argv[1:] if not word.startswith("-")), None) == "reconstruct":
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from species.errors import TreefarmError  # noqa: E402 - after the thread count above

# Each module defines `register(subparsers)`, adding its parsers with `set_defaults(run=function)`: command name ->
# the module that registers it, in the order `farm --help` lists them.
COMMANDS = {
    "tree": "farm.commands.tree",
    "species": "farm.commands.species",
    "generate": "farm.commands.generate",
    "status": "farm.commands.status",
    "validate": "farm.commands.validate",
    "inspect": "farm.commands.inspect",
    "export": "farm.commands.export",
    "render": "farm.commands.render",
    "review": "farm.commands.review",
    "model": "farm.commands.model",
    "library": "farm.commands.library",
    "train": "farm.commands.train",
    "retrain": "farm.commands.train",
    "models": "farm.commands.train",
    "reconstruct": "farm.commands.reconstruct",
    "evaluate": "farm.commands.evaluate",
}
COMMAND_MODULES = list(dict.fromkeys(COMMANDS.values()))

EXIT_USER_ERROR = 2
EXIT_BUG = 1
EXIT_INTERRUPTED = 130
BUG_REPORT = "farm: internal error (a bug): please report it with the traceback above"


class _VersionAction(argparse.Action):
    """--version: the installed treefarm's version, looked up only when asked (start-up time: importlib.metadata
    reads the installed distributions)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings, dest, nargs=0, default=default, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        import importlib.metadata  # here: see the class docstring

        try:
            version = importlib.metadata.version("treefarm")
        except importlib.metadata.PackageNotFoundError:
            version = "(not installed)"  # a source tree run without installing
        print(f"farm (treefarm) {version}")
        parser.exit()


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The `farm` parser with every command; with `command` (a name of COMMANDS), only the module registering it
    is imported and registered (the command's start-up time: each module imports what its own parser lists)."""
    parser = argparse.ArgumentParser(prog="farm", description="treefarm: procedural trees and training data")
    parser.add_argument("--debug", action="store_true",
                        help="print the traceback of every error, a user error's too (before the command)")
    parser.add_argument("--version", action=_VersionAction, help="print the installed treefarm's version and exit")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in [COMMANDS[command]] if command in COMMANDS else COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def _command_named(argv: list[str]) -> str | None:
    """The command word of `argv` (its first word that is not an option: `farm`'s own options take no value)."""
    return next((word for word in argv if not word.startswith("-")), None)


def _named_paths(argv: list[str]) -> list[str]:
    """Absolute forms of the command-line words that may be local paths (`--out=DIR` gives DIR)."""
    words = [word.split("=", 1)[1] if word.startswith("-") and "=" in word else word for word in argv]
    return [os.path.abspath(os.path.expanduser(word)) for word in words
            if word and not word.startswith("-") and "://" not in word]


def _names_a_user_path(exc: OSError, argv: list[str]) -> bool:
    """True when the file error is about a path given on the command line: the path itself, a file inside it,
    or a folder above it (making the parents of --out)."""
    files = [os.path.abspath(str(name)) for name in (exc.filename, exc.filename2) if name is not None]
    for named in _named_paths(argv):
        for file in files:
            if os.path.commonpath([file, named]) in (file, named):
                return True
    return False


def _user_error_message(exc: BaseException, argv: list[str]) -> str | None:
    """The one line a user error is shown as, or None when the exception is a bug."""
    if isinstance(exc, TreefarmError):
        text = str(exc).strip()
        return text.splitlines()[0] if text else type(exc).__name__
    if isinstance(exc, OSError) and _names_a_user_path(exc, argv):
        return f"{exc.filename}: {exc.strerror or exc}"
    return None


def main(argv: list[str] | None = None) -> int:
    """Run `farm ARGV` (the program's own arguments when None) and return its exit status."""
    status = _run_command(sys.argv[1:] if argv is None else list(argv))
    if argv is None:
        # The program ends next, and Python's exit would walk every object the run made (scipy's many included)
        # looking for reference cycles, for memory the system takes back whole anyway: they are frozen out of that
        # last collection. The commands close their own files; atexit handlers still run.
        gc.freeze()
    return status


def _run_command(argv: list[str]) -> int:
    parser = build_parser(_command_named(argv))
    args = parser.parse_args(argv)
    try:
        result = args.run(args)
    except KeyboardInterrupt:
        if args.debug:
            traceback.print_exc()
        print("farm: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as exc:  # sorted here into a user's error (one line) and a bug (traceback)
        message = _user_error_message(exc, argv)
        if message is None or args.debug:
            traceback.print_exc()
        if message is None:
            print(BUG_REPORT, file=sys.stderr)
            return EXIT_BUG
        print(f"farm: error: {message}", file=sys.stderr)
        return EXIT_USER_ERROR
    return int(result or 0)


if __name__ == "__main__":
    sys.exit(main())
