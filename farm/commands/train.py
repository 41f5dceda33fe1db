"""`farm train`, `farm retrain` and `farm models`: the networks trained on the farm's datasets, and their registry.

  farm train TASK --data DIR [DIR...] [--models URI] [--epochs N] [--workers N] [--gpus N] [--address ADDR] [--force]
  farm train TASK --print-data-spec        the job spec that makes TASK's training data (for `farm generate`)
  farm retrain TASK --data DIR [DIR...] [--models URI] [--report DIR]
  farm models list|show NAME [--models URI]

TASK is a task of trainers.tasks.TASKS. --data takes dataset folders, or folders whose
subfolders are datasets (so a retrain picks up the folders added since). --models is the model registry: a folder
(default `registry/`, an embedded MLflow SQLite store) or an MLflow tracking URI. A training run lives in
--run-dir (default `runs/TASK-<digest of data and settings>`): the same command after a crash resumes from its
last checkpoint. The first version of a model becomes its champion unless it scores worse than its baseline
(then a warning says so; --force makes it champion); `farm retrain` promotes a challenger only if it beats the
champion on the champion's frozen held-out split, and writes retrain-report.md and .json. `farm models` only
reads: without --models it lists registry/ (if there is one) and the shipped default models in models/.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

from farm.commands import CommandLineError
from farm.commands.ray_options import add_ray_options, check_workers
from farm.table import format_table, listed
from trainers.tasks import TASKS, get_task, print_data_spec

# What a command runs is imported inside its functions: `farm --help` loads every command module, and training,
# the models and the registry import torch and MLflow (start-up time). The task registry is cheap.


def _description() -> str:
    """The module docstring with the registry's task names where it says where they come from."""
    return __doc__.replace("a task of trainers.tasks.TASKS", listed(TASKS, "or"))


def register(subparsers) -> None:
    description = _description()
    train = subparsers.add_parser("train", help="train a network on datasets, register it (MLflow)",
                                  description=description, formatter_class=argparse.RawDescriptionHelpFormatter)
    _task_arguments(train)
    train.add_argument("--print-data-spec", action="store_true",
                       help="print the job spec that makes this task's training data and exit")
    train.add_argument("--force", action="store_true",
                       help="make a first version champion even when it scores worse than its baseline")
    train.set_defaults(run=run_train)

    retrain = subparsers.add_parser("retrain", help="train a challenger; promote it only if it beats the champion",
                                    description=description, formatter_class=argparse.RawDescriptionHelpFormatter)
    _task_arguments(retrain)
    retrain.add_argument("--report", help="folder for retrain-report.md/.json (default: the run folder)")
    retrain.set_defaults(run=run_retrain)

    models = subparsers.add_parser("models", help="list the model registry, or show one model's versions",
                                   description=description, formatter_class=argparse.RawDescriptionHelpFormatter)
    models.add_argument("action", choices=("list", "show"))
    models.add_argument("name", nargs="?", help="model name (show)")
    models.add_argument("--models", help="model registry folder or MLflow URI (default registry/)")
    models.set_defaults(run=run_models)


def _task_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("task", choices=tuple(TASKS))
    parser.add_argument("--data", nargs="+", metavar="DIR", help="dataset folders (or folders of datasets)")
    parser.add_argument("--models", help="model registry folder or MLflow URI (default registry/)")
    parser.add_argument("--epochs", type=int, help="epochs (default 20, or the champion's for a retrain)")
    parser.add_argument("--batch-size", type=int, help="batch size per worker (default 16)")
    parser.add_argument("--width", type=float,
                        help="network width: TreeSketchNet's multiplier (1 = B0), the U-Net's base channels (16)")
    parser.add_argument("--depth", type=float, help="TreeSketchNet's depth multiplier (default 1 = B0)")
    parser.add_argument("--learning-rate", type=float, help="default: TreeSketchNet 1e-3, pix2pix 2e-4")
    parser.add_argument("--schedule", choices=("constant", "cosine"),
                        help="learning rate over the run: constant (default) or cosine down to 0 by the last epoch")
    parser.add_argument("--seed", type=int, default=0, help="seed of initialisation, order and augmentation")
    parser.add_argument("--time-budget", type=float, metavar="SECONDS", help="stop training after this long")
    add_ray_options(parser, workers_help="Ray Train workers (data-parallel; default 1)", workers_default=1)
    parser.add_argument("--gpus", type=int, default=0, help="GPUs over all workers (default 0: CPU)")
    parser.add_argument("--run-dir", help="the run's folder (default runs/TASK-<digest>); the same one resumes")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def dataset_folders(paths: list[str]) -> list[str]:
    """Each path that is a dataset (has manifest.json or a job record), else its subfolders that are, sorted."""
    from farm.dataset.manifest import JOB_RECORD
    from farm.dataset.storage import Location

    out = []
    for path in paths:
        location = Location.resolve(path)
        if location.exists("manifest.json") or location.exists(JOB_RECORD):
            out.append(path)
            continue
        children = [name for name in location.subfolders() if location.exists(f"{name}/manifest.json")]
        if not children:
            out.append(path)  # the task's check names what is wrong with it
        out += [f"{path.rstrip('/')}/{name}" for name in children]
    return out


def _settings(args: argparse.Namespace, base: dict | None = None):
    from trainers.networks import TrainSettings

    values = dict(base or {})
    for key, name in (("epochs", "epochs"), ("batch_size", "batch_size"), ("width", "width"), ("depth", "depth"),
                      ("learning_rate", "learning_rate"), ("schedule", "schedule"), ("time_budget", "time_budget_s")):
        if getattr(args, key) is not None:
            values[name] = getattr(args, key)
    values["seed"] = args.seed
    if values.get("width") is not None and get_task(args.task).network != "sketchnet":
        values["width"] = int(values["width"]) if float(values["width"]).is_integer() else values["width"]
    return TrainSettings.from_dict(values)


def _run_dir(args: argparse.Namespace, folders: list[str], settings, kind: str) -> Path:
    if args.run_dir:
        return Path(args.run_dir)
    key = json.dumps({"kind": kind, "task": args.task, "data": [str(Path(f).resolve()) if "://" not in f else f
                                                                for f in folders],
                      "settings": settings.to_dict(), "models": args.models}, sort_keys=True)
    return Path("runs") / f"{args.task}-{kind}-{hashlib.sha256(key.encode()).hexdigest()[:10]}"


def _need_data(args: argparse.Namespace) -> list[str]:
    if not args.data:
        raise CommandLineError(f"no training data: pass --data DIR [DIR...]; make a dataset with `farm train "
                               f"{args.task} --print-data-spec > spec.yaml && farm generate spec.yaml --out DIR`")
    return dataset_folders(args.data)


def run_train(args: argparse.Namespace) -> int:
    if args.print_data_spec:
        sys.stdout.write(print_data_spec(args.task))
        return 0
    folders = _need_data(args)
    check_workers(args.workers)
    from farm.dataset.manifest import code_version
    from farm.pipeline import ray_connection
    from trainers.data import open_data
    from trainers.models import register_result
    from trainers.registry import open_registry
    from trainers.training import checked_split, train

    settings = _settings(args)
    # Before Ray starts: a registry that cannot be opened or data that cannot train this task (too few trees to
    # put one in each part of the split) fail at once.
    checked_split(args.task, open_data(args.task, folders))
    registry = open_registry(args.models)
    run_dir = _run_dir(args, folders, settings, "train")
    with ray_connection(args.address, args.workers, log_to_driver=False):
        result = train(args.task, folders, settings=settings, run_dir=run_dir, workers=args.workers,
                       gpus=args.gpus, progress=not args.quiet)
    version = register_result(registry, result, code_version=code_version(), force=args.force)
    _print_result(args.task, result, version, registry)
    return 0


def _print_result(task: str, result, version, registry) -> None:
    from trainers.model_tables import below_baseline
    from trainers.models import counted

    network = result.network
    rows = [[key, f"{result.test_metrics[key]:.4g}", f"{result.baseline_metrics.get(key, float('nan')):.4g}"]
            for key in sorted(result.test_metrics)]
    resumed = "" if result.resumed_from_epoch is None else f", resumed after epoch {result.resumed_from_epoch}"
    print(f"{task}: {counted(result.epochs, 'epoch')}, {counted(result.steps, 'step')} in {result.seconds:.0f} s"
          f"{resumed}; {counted(result.summary['trees']['train'], 'training tree')} "
          f"({result.summary['rejected']} rejected by reviewers); run folder {result.run_dir}")
    print(format_table(["held-out metric", "model", "mean baseline"], rows))
    aliases = ", ".join(version.aliases) or "no alias"
    print(f"registered {version.name} v{version.version} ({aliases}) in {registry.label}; decided by "
          f"{network.primary} ({'higher' if network.higher_is_better else 'lower'} is better)")
    worse = below_baseline(version)
    if worse:
        first = version.version == 1 and not version.is_champion
        print(f"warning: {worse}" + (f"; not made champion (a first version must beat its baseline): train "
                                     f"longer or on more data, or pass --force" if first else ""), file=sys.stderr)


def run_retrain(args: argparse.Namespace) -> int:
    folders = _need_data(args)
    check_workers(args.workers)
    from farm.dataset.manifest import code_version
    from farm.pipeline import ray_connection
    from trainers.data import open_data
    from trainers.models import retrain
    from trainers.networks import TrainSettings
    from trainers.registry import open_registry
    from trainers.training import checked_split

    training_data = open_data(args.task, folders)
    registry = open_registry(args.models)
    settings = None
    if any(getattr(args, key) is not None for key in ("epochs", "batch_size", "width", "time_budget")):
        settings = _settings(args, TrainSettings().to_dict())
    champion = registry.champion(args.task)
    if champion is None:  # a first version splits the data itself (a challenger reapplies the champion's split)
        checked_split(args.task, training_data)
    kind = f"retrain-v{champion.version}" if champion is not None else "retrain-new"
    run_dir = _run_dir(args, folders, settings or TrainSettings(seed=args.seed), kind)
    with ray_connection(args.address, args.workers, log_to_driver=False):
        outcome = retrain(args.task, folders, registry, run_dir=run_dir, settings=settings, workers=args.workers,
                          gpus=args.gpus, code_version=code_version(), progress=not args.quiet,
                          report_dir=args.report)
    report = Path(args.report) if args.report else run_dir
    kept = "champion kept" if outcome.champion_version is not None else "not made champion"
    print(f"{args.task}: challenger v{outcome.challenger_version} "
          f"{'promoted to champion' if outcome.promoted else f'registered, {kept}'}: {outcome.reason}")
    print(f"report: {report / 'retrain-report.md'}")
    return 0


def run_models(args: argparse.Namespace) -> int:
    """List or show models, reading only: a registry folder that does not hold one is never created."""
    from trainers.model_tables import format_model_versions, format_models_table, format_shipped_model
    from trainers.models import DEFAULT_MODELS, holds_shipped_models, shipped_models
    from trainers.registry import DATABASE_FILE, DEFAULT_FOLDER, open_registry

    if args.action == "show" and not args.name:
        raise CommandLineError("farm models show needs a model name: farm models show NAME (see farm models list)")
    shipped_folder = DEFAULT_MODELS if args.models is None else Path(args.models)
    shipped = []
    if args.models is None or holds_shipped_models(args.models):
        shipped = shipped_models(shipped_folder)
    registry = None
    if args.models is not None and not shipped:
        registry = open_registry(args.models, create=False)  # one line, exit 2, when there is none
    elif args.models is None and (Path(DEFAULT_FOLDER) / DATABASE_FILE).exists():
        registry = open_registry(None, create=False)
    if args.action == "list":
        print(format_models_table(registry, shipped, shipped_from=str(shipped_folder)))
        if registry is None and args.models is None:
            print(f"(no model registry in {DEFAULT_FOLDER}/ here: `farm train` makes one)")
        return 0
    if registry is not None and args.name in registry.names():
        print(format_model_versions(registry, args.name))
        return 0
    found = next((v for v in shipped if v.name == args.name), None)
    if found is None:
        if registry is not None:
            registry.versions(args.name)  # raises a RegistryError naming the models the registry holds
        known = ", ".join(v.name for v in shipped) or "none"
        raise CommandLineError(f"no model {args.name!r} in {shipped_folder}: it ships {known}")
    print(format_shipped_model(found, str(shipped_folder)))
    return 0
