"""Start-up of the `farm` command line (issue 48, point 13): each command's `--help`, and one cheap real run per
command where it has one, timed whole as a user runs them (`python -m farm.cli ...`, a fresh interpreter each).

Table 1: every command's `--help` (the parser and the command modules' imports). Table 2: cheap runs: `farm
--version`, `farm species`, a tree, `farm reconstruct` on a missing file and on tree1.xyz (11,855 points; left out
where ../shared/data/pointclouds/ is missing), and for the commands with no cheap real run a bad argument (refused
before their work starts). With `--against CHECKOUT` every case also runs from that checkout (another commit's
tree), interleaved run by run with this one, so that a loaded machine slows both alike. Which libraries each
command may import is tests/farm/test_startup.py's.

Run: python -m benchmarks.bench_startup [--repeats 5] [--against /path/to/other/checkout]
"""
from __future__ import annotations

import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.harness import ROOT, Benchmark, Timing, arguments

TREE1 = ROOT.parent / "shared" / "data" / "pointclouds" / "tree1.xyz"

# (label, argv; {tmp} is a scratch folder): a cheap real run of a command, or a bad argument where it has none
CHEAP_RUNS = [
    ("farm --version", ["--version"]),
    ("farm species", ["species"]),
    ("farm tree (maple)", ["tree", "--species", "maple", "--out", "{tmp}/maple.glb"]),
    ("farm reconstruct (missing file)", ["reconstruct", "{tmp}/missing.xyz", "--out", "{tmp}/tree.glb"]),
    ("farm reconstruct (tree1.xyz)", ["reconstruct", str(TREE1), "--out", "{tmp}/tree1.glb"]),
    ("farm status (no job)", ["status", "{tmp}/none"]),
    ("farm generate (--trees 0)", ["generate", "--trees", "0", "--out", "{tmp}/job", "--quiet"]),
    ("farm train (--workers 0)", ["train", "sketchnet", "--data", "{tmp}/none", "--workers", "0"]),
    ("farm evaluate (--workers 0)", ["evaluate", "--data", "{tmp}/none", "--out", "{tmp}/r", "--workers", "0"]),
]


def commands(checkout: Path) -> list[str]:
    """The subcommands of the checkout's `farm` parser."""
    code = ("from farm.cli import build_parser; parser = build_parser(); "
            "print(' '.join(next(a for a in parser._actions if a.dest == 'command').choices))")
    return subprocess.run([sys.executable, "-c", code], cwd=checkout, env=_env(checkout), capture_output=True,
                          text=True, check=True).stdout.split()


def _env(checkout: Path) -> dict:
    return {"PYTHONPATH": str(checkout), "PATH": "/usr/bin:/bin", "HOME": str(Path.home())}


def run_once(checkout: Path, argv: list[str]) -> tuple[float, float]:
    """(wall, CPU) seconds of `python -m farm.cli ARGV` from `checkout`, in a fresh scratch folder."""
    with tempfile.TemporaryDirectory(prefix="bench-startup-") as tmp:
        words = [word.format(tmp=tmp) for word in argv]
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "farm.cli", *words], cwd=tmp, env=_env(checkout),
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)


def timed(cases: list[tuple[str, list[str]]], checkouts: list[Path], repeats: int) -> dict:
    """(label, checkout) -> Timing, each case run `repeats` times from every checkout, interleaved."""
    runs: dict = {(label, checkout): ([], []) for label, _ in cases for checkout in checkouts}
    for _ in range(repeats):
        for label, argv in cases:
            for checkout in checkouts:
                wall, cpu = run_once(checkout, argv)
                runs[label, checkout][0].append(wall)
                runs[label, checkout][1].append(cpu)
    return {key: Timing(tuple(wall), tuple(cpu)) for key, (wall, cpu) in runs.items()}


def rows(cases: list[tuple[str, list[str]]], checkouts: list[Path], timings: dict) -> list[list]:
    out = []
    for label, _ in cases:
        row = [label]
        for checkout in checkouts:
            timing = timings[label, checkout]
            row += [f"{timing.median:.2f}", f"{timing.cpu_median:.2f}"]
        out.append(row)
    return out


def main() -> None:
    parser = arguments(__doc__.splitlines()[0], repeats=5)
    parser.add_argument("--against", type=Path, help="another checkout to time beside this one, interleaved")
    args = parser.parse_args()
    checkouts = [ROOT] + ([args.against.resolve()] if args.against else [])
    columns = ["command"] + [f"{name} {kind}" for name in ["this"] + (["against"] if args.against else [])
                             for kind in ("wall s", "CPU s")]
    bench = Benchmark("startup", "farm's start-up: each command's --help and a cheap run, whole processes", args)
    helps = [(f"farm {command} --help", [command, "--help"]) for command in commands(ROOT)]
    cheap = [(label, argv) for label, argv in CHEAP_RUNS if str(TREE1) not in argv or TREE1.is_file()]
    help_timings = timed(helps, checkouts, args.repeats)
    cheap_timings = timed(cheap, checkouts, args.repeats)
    against = [f"against: {args.against.resolve()}"] if args.against else []
    bench.table(f"--help, median of {args.repeats}", columns, rows(helps, checkouts, help_timings), against)
    bench.table(f"cheap runs, median of {args.repeats}", columns, rows(cheap, checkouts, cheap_timings), against)
    for label in ("farm species", "farm reconstruct (missing file)", "farm reconstruct (tree1.xyz)"):
        if (label, ROOT) in cheap_timings:
            bench.figure(f"{label} seconds", cheap_timings[label, ROOT].median, "s")
    bench.write()


if __name__ == "__main__":
    main()
