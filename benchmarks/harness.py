"""What every benchmark shares: thread pinning, timing a case over repeats, printing tables beside their references,
and the results file `benchmarks/results/NAME.json` (machine, versions, git commit, command, tables, figures).

A benchmark is a module run as `python -m benchmarks.bench_NAME [options]` from the repository root:

    from benchmarks.harness import Benchmark, pin_threads
    pin_threads()                        # before numpy, OpenCV and Mesa start their thread pools
    import numpy as np  # noqa: E402
    ...
    bench = Benchmark("weber_penn", "Weber-Penn grow and mesh, one core", args)
    timing = time_case(lambda: grow_and_mesh(params), repeats=args.repeats)
    bench.table("per dictionary", ["dictionary", "total ms", "reference"], rows)
    bench.write()

Imports only the standard library at the top, so that `pin_threads` can run before numpy loads.
"""
from __future__ import annotations

import argparse
import dataclasses
import datetime
import importlib.metadata
import json
import os
import platform
import shlex
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Callable, Sequence

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
RESULTS_FORMAT = "treefarm-benchmark-results"
# Thread pools that start with the first import of numpy's BLAS, OpenMP code, numexpr and Mesa's llvmpipe.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS",
                    "LP_NUM_THREADS")
# Distributions whose versions a result records (those installed).
VERSIONED = ("numpy", "scipy", "trimesh", "pyarrow", "ray", "torch", "onnxruntime", "pyrender",
             "opencv-contrib-python-headless", "usd-core", "pycolmap")


def pin_threads(threads: int = 1, one_core: bool = False) -> None:
    """Every thread pool to `threads` threads (environment variables, read when numpy, OpenCV's OpenMP and Mesa
    load: call this first); with `one_core`, the process is also bound to one CPU, so that nothing it starts
    later (Ray's driver threads, a GL context) uses a second one."""
    for variable in THREAD_VARIABLES:
        os.environ[variable] = str(threads)
    if one_core and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})


def unpin_cores() -> None:
    """Every CPU of the machine to this process again (after `pin_threads(one_core=True)`), for a part that
    measures scaling over workers."""
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, range(os.cpu_count() or 1))


@dataclasses.dataclass(frozen=True)
class Timing:
    """Seconds of each repeat of one case, wall clock and this process's CPU time (all its threads)."""

    wall: tuple[float, ...]
    cpu: tuple[float, ...]
    result: Any = dataclasses.field(default=None, compare=False, repr=False)  # what the last repeat returned

    @property
    def median(self) -> float:
        return statistics.median(self.wall)

    @property
    def cpu_median(self) -> float:
        return statistics.median(self.cpu)

    @property
    def spread(self) -> float:
        """Half the range of the repeats, as a share of the median: 0.05 reads "within 5 % either way"."""
        return (max(self.wall) - min(self.wall)) / 2 / self.median if self.median > 0 else 0.0

    def scaled(self, per: float) -> Timing:
        """The same timing per unit of work (a view, a tree): every repeat divided by `per`."""
        return Timing(tuple(s / per for s in self.wall), tuple(s / per for s in self.cpu), self.result)

    def ms(self, cpu: bool = False) -> float:
        return 1000.0 * (self.cpu_median if cpu else self.median)

    def to_dict(self) -> dict:
        return {"median_s": self.median, "cpu_median_s": self.cpu_median, "spread": self.spread,
                "repeats": len(self.wall), "wall_s": list(self.wall), "cpu_s": list(self.cpu)}


def time_case(run: Callable[[], Any], repeats: int, warmup: int = 0) -> Timing:
    """`run()` timed `repeats` times after `warmup` untimed calls (imports, caches, a GL context)."""
    if repeats < 1:
        raise ValueError(f"repeats = {repeats}: at least 1")
    for _ in range(warmup):
        run()
    wall, cpu, result = [], [], None
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        result = run()
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    return Timing(tuple(wall), tuple(cpu), result)


def arguments(description: str, repeats: int | None = None) -> argparse.ArgumentParser:
    """A parser with the options every benchmark takes: `--no-results` (print only) and, with a default number
    of `repeats`, `--repeats N`. The benchmark adds its own."""
    parser = argparse.ArgumentParser(description=description, formatter_class=argparse.RawDescriptionHelpFormatter)
    if repeats is not None:
        parser.add_argument("--repeats", type=int, default=repeats, help=f"timed runs per case (default {repeats})")
    parser.add_argument("--no-results", action="store_true",
                        help=f"print the tables only; do not write {RESULTS.relative_to(ROOT)}/NAME.json")
    return parser


# ---------------------------------------------------------------- where it ran
def machine() -> dict:
    """CPU model, cores (and those this process may use), memory, GPU, operating system and load average."""
    cpu = platform.processor() or platform.machine()
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.is_file():
        models = [line.split(":", 1)[1].strip() for line in cpuinfo.read_text().splitlines()
                  if line.startswith("model name")]
        cpu = models[0] if models else cpu
    memory = None
    if hasattr(os, "sysconf") and "SC_PHYS_PAGES" in os.sysconf_names:
        memory = round(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30, 1)
    usable = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {"cpu": cpu, "cores": os.cpu_count(), "cores_usable": usable, "memory_gib": memory, "gpu": gpus(),
            "system": f"{platform.system()} {platform.release()}",
            "load_average": round(os.getloadavg()[0], 2) if hasattr(os, "getloadavg") else None}


def gpus() -> str:
    """The GPUs nvidia-smi lists, or "none"."""
    smi = shutil.which("nvidia-smi")
    if smi is None:
        return "none"
    listed = subprocess.run([smi, "-L"], capture_output=True, text=True, check=False).stdout.strip()
    return "; ".join(listed.splitlines()) or "none"


def versions() -> dict:
    """Python's version and those of the installed distributions in VERSIONED."""
    out = {"python": platform.python_version()}
    for name in VERSIONED:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            continue
    return out


def git_commit() -> dict:
    """The checkout's commit and whether files differ from it (None where this is no git checkout)."""
    def git(*args: str) -> str | None:
        try:
            done = subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=True)
        except (OSError, subprocess.CalledProcessError):
            return None
        return done.stdout.strip()

    commit = git("rev-parse", "HEAD")
    changed = git("status", "--porcelain", "--untracked-files=no")
    return {"commit": commit, "modified": bool(changed) if changed is not None else None}


def command_line() -> str:
    """How this benchmark was started, as a user would type it from the repository root."""
    main = sys.modules.get("__main__")
    module = getattr(getattr(main, "__spec__", None), "name", None)
    start = f"python -m {module}" if module else f"python {shlex.quote(sys.argv[0])}"
    return " ".join([start, *map(shlex.quote, sys.argv[1:])])


# ---------------------------------------------------------------- what it measured
def cell(value: Any) -> Any:
    """A table cell as printed and stored: floats to 3 significant digits past the point, timings as their
    median in ms, everything else as it is (str, int, None)."""
    if isinstance(value, Timing):
        return round(value.ms(), 1)
    if isinstance(value, float):
        return float(f"{value:.4g}") if abs(value) < 1000 else round(value, 1)
    return value


@dataclasses.dataclass
class Benchmark:
    """One run of one benchmark: its tables, headline figures and notes, printed as they come and written with
    the machine, versions and commit by `write`."""

    name: str                        # the results file's stem: benchmarks/results/NAME.json
    title: str                       # one line: what it measures
    options: argparse.Namespace | None = None
    tables: list[dict] = dataclasses.field(default_factory=list)
    figures: dict[str, dict] = dataclasses.field(default_factory=dict)
    notes: list[str] = dataclasses.field(default_factory=list)

    def table(self, title: str, columns: Sequence[str], rows: Sequence[Sequence[Any]],
              notes: Sequence[str] = ()) -> None:
        """Print a table (its title, the rows under their columns, then its notes: references, targets) and keep
        it for the results file."""
        from farm.table import format_table  # the CLI's table printer; farm loads numpy, after pin_threads

        cells = [[cell(v) for v in row] for row in rows]
        print(f"\n{title}")
        print(format_table(list(columns), cells))
        for note in notes:
            print(f"  {note}")
        self.tables.append({"title": title, "columns": list(columns), "rows": cells, "notes": list(notes)})

    def figure(self, name: str, value: float, unit: str, reference: str = "") -> None:
        """A headline figure (what the README quotes): printed as one line and kept by name."""
        print(f"{name}: {cell(float(value))} {unit}" + (f" ({reference})" if reference else ""))
        self.figures[name] = {"value": cell(float(value)), "unit": unit, "reference": reference}

    def note(self, text: str) -> None:
        print(text)
        self.notes.append(text)

    def record(self) -> dict:
        return {"format": RESULTS_FORMAT, "name": self.name, "title": self.title, "command": command_line(),
                "options": {k: str(v) if isinstance(v, Path) else v for k, v in vars(self.options or {}).items()},
                "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
                "machine": machine(), "versions": versions(), "git": git_commit(),
                "tables": self.tables, "figures": self.figures, "notes": self.notes}

    def write(self, folder: Path = RESULTS) -> Path | None:
        """benchmarks/results/NAME.json (unless the options say --no-results); returns its path."""
        if getattr(self.options, "no_results", False):
            return None
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"{self.name}.json"
        path.write_text(json.dumps(self.record(), indent=1) + "\n")
        print(f"\nresults: {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}")
        return path


def read_results(path: Path) -> dict:
    """A results file, checked to be one (a DatasetError naming the file otherwise)."""
    # Here, not at the top: the harness's top imports only the standard library, so pin_threads runs before numpy.
    from farm.dataset import parse_format_json

    return parse_format_json(path.read_bytes(), RESULTS_FORMAT, source=str(path),
                             hint="write it with benchmarks.harness.Benchmark.write")
