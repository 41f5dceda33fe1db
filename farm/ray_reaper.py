"""A watchdog beside a driver that started its own local Ray: when the driver ends, however it ends (SIGKILL too),
every process it started ends with it. Ray's agents (dashboard and runtime-env) outlive a killed driver otherwise.

Input: the driver's pid and a pipe from it (end of file: the driver is gone); output: none. Linux only (/proc).
"""
from __future__ import annotations

import os
import select
import signal
import subprocess
import sys

__all__ = ["start_reaper", "descendants"]

# How often the watchdog refreshes the driver's process tree while the driver lives.
POLL_SECONDS = 0.5


def _process_table() -> dict[int, tuple[int, str]]:
    """pid -> (parent pid, start time in clock ticks) of every process readable in /proc."""
    table = {}
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/stat") as stat:
                fields = stat.read().rsplit(")", 1)[1].split()
        except OSError:  # the process ended while we read the table
            continue
        table[int(name)] = (int(fields[1]), fields[19])
    return table


def descendants(pid: int) -> dict[int, str]:
    """The processes under `pid` (children, theirs, ...), as pid -> start time (to tell a reused pid)."""
    table = _process_table()
    children: dict[int, list[int]] = {}
    for child, (parent, _) in table.items():
        children.setdefault(parent, []).append(child)
    found, stack = {}, list(children.get(pid, []))
    while stack:
        child = stack.pop()
        found[child] = table[child][1]
        stack.extend(children.get(child, []))
    return found


def start_reaper() -> subprocess.Popen | None:
    """Start the watchdog of this process; it holds the read end of a pipe whose write end only this process has.
    None where there is no /proc."""
    if not os.path.isdir("/proc"):
        return None
    return subprocess.Popen([sys.executable, "-m", "farm.ray_reaper", str(os.getpid())], stdin=subprocess.PIPE,
                            start_new_session=True, close_fds=True)


def _watch(driver: int) -> None:
    known: dict[int, str] = {}
    while True:
        ready, _, _ = select.select([sys.stdin], [], [], POLL_SECONDS)
        if ready and not os.read(sys.stdin.fileno(), 4096):
            break  # end of file: the driver exited or was killed
        known.update(descendants(driver))
    alive = _process_table()
    for pid, started in known.items():
        if pid != os.getpid() and alive.get(pid, (None, None))[1] == started:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:  # it ended on its own meanwhile
                pass


if __name__ == "__main__":
    _watch(int(sys.argv[1]))
