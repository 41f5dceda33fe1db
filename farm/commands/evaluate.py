"""`farm evaluate`: every reconstruction method scored on the held-out trees of datasets (and on real inputs).

  farm evaluate --data DIR [DIR...] --out REPORT [--methods sketch-depth,params,two-view,cloud[,photos]]
                [--models URI] [--trees N] [--part test|val|all] [--inputs DIR] [--fit-evals N] [--workers N]
                [--address ADDR]
  farm evaluate --print-data-spec > eval.yaml       a job spec whose dataset serves every method
  farm evaluate compare REPORT_A REPORT_B [--fail-if-worse METRIC[:TOLERANCE] ...]

Held-out trees: the trainers' split (a hash of spec digest and tree id), part `test` by default; `--part all` for a
dataset no model trained on. A rerun into the same REPORT resumes (finished trees are not repeated). REPORT gets
metrics.parquet, summary.md, metrics_by_method.png, metrics_by_species.png, gallery_METHOD.png, sweep.png and
panels/; `farm review REPORT` shows it. docs/evaluation.md has the layout and the metrics.
"""
from __future__ import annotations

import argparse
import sys

from reconstruct.fit_budget import DEFAULT_FIT_EVALS
from reconstruct.methods import METHODS

from farm.commands import CommandLineError, check_flag_int
from farm.commands.ray_options import add_ray_options, check_workers

# What a command runs is imported inside its functions: `farm --help` loads every command module (start-up time).

DEFAULT_METHODS = "sketch-depth,params,two-view,cloud"


def register(subparsers) -> None:
    parser = subparsers.add_parser("evaluate", help="score every reconstruction method on held-out trees; "
                                   "`evaluate compare A B`", description=__doc__,
                                   formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("action", nargs="*", metavar="compare A B", help="compare two reports")
    parser.add_argument("--data", nargs="+", default=[], metavar="DIR", help="dataset folders (farm generate)")
    parser.add_argument("--methods", default=DEFAULT_METHODS,
                        help=f"comma-separated, of {', '.join(METHODS)} (default {DEFAULT_METHODS})")
    parser.add_argument("--models", help="model registry URI or folder (default: the shipped models/)")
    parser.add_argument("--out", help="the report folder (a rerun resumes it)")
    parser.add_argument("--trees", type=int, help="at most N held-out trees per dataset, picked across its species")
    parser.add_argument("--part", default="test", help="the split part: test (default), val, or all")
    parser.add_argument("--inputs", help="a folder of real clouds and sketches (docs/evaluation.md)")
    parser.add_argument("--fit-evals", type=int, default=DEFAULT_FIT_EVALS, metavar="N",
                        help="candidate trees each drawing method grows and redraws to fit its drawing "
                             f"(default {DEFAULT_FIT_EVALS}; 0: the methods' first guesses)")
    add_ray_options(parser, workers_help="trees evaluated at once (default: the CPUs)")
    parser.add_argument("--sweep-step", type=float, default=5.0,
                        help="rotation sweep step, degrees (default 5: 72 views; 0: no sweep)")
    parser.add_argument("--surface-samples", type=int, default=20_000,
                        help="surface samples per mesh for the surface distances (default 20000; 0: none)")
    parser.add_argument("--print-data-spec", action="store_true", help="print an evaluation dataset's job spec")
    parser.add_argument("--fail-if-worse", action="append", default=[], metavar="METRIC[:TOLERANCE]",
                        help="compare: exit 1 when B is worse than A on METRIC (all: any) by more than TOLERANCE")
    parser.set_defaults(run=run)


def _compare(args) -> int:
    from farm.evaluate.compare import broken_gates, compare_reports, format_changes, parse_gate

    if len(args.action) != 3:
        raise CommandLineError(f"farm evaluate compare takes two report folders (got {len(args.action) - 1})")
    gates = [parse_gate(text) for text in args.fail_if_worse]
    changes = compare_reports(args.action[1], args.action[2])
    print(format_changes(changes))
    broken = broken_gates(changes, gates)
    for change in broken:
        print(f"worse: {change.method} {change.metric} {change.a:.4f} -> {change.b:.4f}", file=sys.stderr)
    return 1 if broken else 0


def run(args: argparse.Namespace) -> int:
    from farm.evaluate.job import evaluation_data_spec, plan_evaluation, run_evaluation
    from farm.evaluate.methods import EvalSettings

    if args.action:
        if args.action[0] != "compare":
            raise CommandLineError(f"unexpected argument {args.action[0]!r}: use `farm evaluate --data DIR ... --out "
                                   "REPORT` or `farm evaluate compare A B`")
        return _compare(args)
    if args.fail_if_worse:
        raise CommandLineError("--fail-if-worse is a `farm evaluate compare A B` option")
    if args.print_data_spec:
        sys.stdout.write(evaluation_data_spec())
        return 0
    if not args.out:
        raise CommandLineError("--out REPORT_DIR is required (the report folder)")
    check_workers(args.workers)
    check_flag_int("--surface-samples", args.surface_samples, 0)
    if not 0 <= args.sweep_step <= 360:
        raise CommandLineError(f"--sweep-step {args.sweep_step} is invalid: allowed degrees in (0, 360], or 0 for "
                               "no sweep")
    settings = EvalSettings(surface_samples=args.surface_samples, fit_evals=args.fit_evals)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    plan = plan_evaluation(args.data, methods, trees=args.trees, part=args.part, inputs=args.inputs,
                           settings=settings, models=args.models)
    for line in plan.skipped:
        print(line)
    outcome = run_evaluation(plan, args.out, models=args.models, settings=settings, workers=args.workers,
                             address=args.address, sweep_step=args.sweep_step or None)
    rows = outcome["rows"]
    counts = rows["status"].value_counts().to_dict()
    for _, row in rows[rows["status"] == "error"].iterrows():
        print(f"error in {row['method']} {row['tree_id']}:\n{row['error']}", file=sys.stderr)
    print((args.out.rstrip("/") + "/summary.md:\n") + _metrics_block(outcome["report"]["summary"]))
    print(f"{len(rows)} rows ({counts.get('ok', 0)} ok, {counts.get('failed', 0)} failed, {counts.get('error', 0)} "
          f"errors; {outcome['done_before']} from before) -> {args.out} ({', '.join(sorted(outcome['report']))})")
    return 1 if counts.get("error", 0) else 0


def _metrics_block(summary_path) -> str:
    """The summary's metric table (the first fenced block of summary.md)."""
    text = summary_path.read_text()
    start = text.find("```\n")
    end = text.find("```", start + 4)
    return text[start + 4:end] if start >= 0 and end > start else ""
