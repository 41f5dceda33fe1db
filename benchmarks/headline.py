"""The headline set that `make bench` runs: one short run of each benchmark behind a figure the README quotes,
each in a process of its own (so each pins its own threads), then docs/performance.md regenerated from the results.

The settings are short enough that the whole set takes a few minutes on 2 cores; the full runs behind the README's
figures are the same modules with their default options. Each needs only what a checkout has after `make env`:
the shipped models in models/ and data the benchmark makes itself (bench_train generates its small training set
into out/bench-train-data once). Two parts of the README's figures are not reproduced here:
- reconstruct_cloud: the tree1.xyz table needs AdTree's sample cloud, which is not in the repository (it is read
  from ../shared/data/pointclouds/ beside the checkout, or --tree1 PATH); without it only the synthetic scans run.
- train_throughput: one network (the silhouette U-Net) on a 15 s window per setting, where the README's row
  quotes two networks on 40 s windows. Each of the three settings starts a Ray Train run of its own, whose
  start-up is paid on top of the window: one network takes about two minutes on 2 cores (half a minute more the
  first time, which generates its 40 training trees), two would take four.
The training quality row (`make models`) trains each network for minutes and has no short run.
Run: python -m benchmarks.headline [NAME ...]
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import time
from dataclasses import dataclass

from benchmarks.harness import ROOT


@dataclass(frozen=True)
class HeadlineRun:
    name: str                    # the results file's stem
    module: str                  # benchmarks.<module>
    options: tuple[str, ...]     # the short settings

    def command(self) -> list[str]:
        return [sys.executable, "-m", f"benchmarks.{self.module}", *self.options]


HEADLINE = (
    HeadlineRun("weber_penn", "bench_weber_penn", ("--repeats", "3")),
    HeadlineRun("mesh", "bench_mesh", ("--repeats", "5")),
    HeadlineRun("colonization", "bench_colonization", ("--runs", "2")),
    HeadlineRun("render", "bench_render", ("--repeats", "2", "--sizes", "256", "--no-cycles")),
    HeadlineRun("farm", "bench_farm", ("--trees-per-species", "2", "--repeats", "1")),
    HeadlineRun("library", "bench_library", ("--no-scaling", "maple", "palm", "sassafras")),
    HeadlineRun("inference", "bench_inference", ("--widths", "16", "--repeats", "3")),
    HeadlineRun("reconstruct", "bench_reconstruct", ("--trees", "4", "--sweep-trees", "1", "--sweep-views", "12",
                                                     "--sheet-trees", "1")),
    HeadlineRun("reconstruct_cloud", "bench_reconstruct_cloud", ("--sizes", "10000", "--trees", "3",
                                                                 "--pytlidar-timeout", "0")),
    HeadlineRun("train_throughput", "bench_train", ("--skip-quality", "--tasks", "pix2pix-silhouette",
                                                    "--throughput-seconds", "15", "--generate", "40",
                                                    "--data-root", "out/bench-train-data")),
    HeadlineRun("startup", "bench_startup", ("--repeats", "3")),
)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help=f"only these ({', '.join(run.name for run in HEADLINE)})")
    args = parser.parse_args(argv)
    unknown = set(args.names) - {run.name for run in HEADLINE}
    if unknown:
        parser.error(f"unknown headline benchmark(s) {', '.join(sorted(unknown))}; known: "
                     f"{', '.join(run.name for run in HEADLINE)}")
    failed = []
    for run in HEADLINE:
        if args.names and run.name not in args.names:
            continue
        print(f"\n=== {run.name}: python -m benchmarks.{run.module} {' '.join(run.options)}", flush=True)
        start = time.perf_counter()
        if subprocess.run(run.command(), cwd=ROOT, check=False).returncode != 0:
            failed.append(run.name)
        print(f"=== {run.name}: {time.perf_counter() - start:.0f} s", flush=True)
    subprocess.run([sys.executable, "-m", "benchmarks.performance_doc"], cwd=ROOT, check=True)
    if failed:
        print(f"failed: {', '.join(failed)}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
