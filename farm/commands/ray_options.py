"""The options of every command that runs on Ray, declared once: `--workers N` (how much runs at once) and
`--address ADDR` (a cluster to join instead of a local Ray), and the one check of `--workers`.

Each command says in its own help what a worker is for it (actors, tasks, trees at once, Ray Train workers).
"""
from __future__ import annotations

from farm.commands import CommandLineError

__all__ = ["ADDRESS_HELP", "add_ray_options", "check_workers"]

ADDRESS_HELP = "join this Ray cluster instead of starting a local one"


def add_ray_options(parser, workers_help: str, address_help: str = ADDRESS_HELP,
                    workers_default: int | None = None) -> None:
    """Add `--workers` (an int, `workers_default` when not given) and `--address` to `parser`: an
    `argparse.ArgumentParser` or one of its argument groups."""
    parser.add_argument("--workers", type=int, default=workers_default, help=workers_help)
    parser.add_argument("--address", help=address_help)


def check_workers(workers: int | None) -> int | None:
    """`workers` when it is None (the command's default) or >= 1; else a CommandLineError naming the value."""
    if workers is not None and workers < 1:
        raise CommandLineError(f"--workers {workers} is invalid: allowed an integer >= 1")
    return workers
