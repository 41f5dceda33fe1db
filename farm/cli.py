"""The `farm` command line: one subcommand module per job in `farm/commands/`.

Errors a user can act on are printed as one line (`farm: error: ...`) with exit status 2, never a traceback.
"""
from __future__ import annotations

import argparse
import importlib
import sys

# Each module defines `register(subparsers)`, adding its parser with `set_defaults(run=function)`.
COMMAND_MODULES = [
    "farm.commands.tree",
    "farm.commands.species",
    "farm.commands.generate",
    "farm.commands.status",
    "farm.commands.validate",
    "farm.commands.inspect",
    "farm.commands.export",
    "farm.commands.render",
    "farm.commands.review",
    "farm.commands.library",
]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="farm", description="treefarm: procedural trees and training data")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        result = args.run(args)
    except KeyboardInterrupt:
        print("farm: interrupted", file=sys.stderr)
        return 130
    except (ValueError, OSError, KeyError) as exc:  # user-facing errors: bad values, files, names
        message = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        print(f"farm: error: {message}", file=sys.stderr)
        return 2
    return int(result or 0)


if __name__ == "__main__":
    sys.exit(main())
