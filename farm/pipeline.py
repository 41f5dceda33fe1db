"""The generation pipeline: plan shards, run them on Ray actors (one renderer each), write the manifest last.

Input: a job spec (a `farm.jobs.PipelineSpec`: JobSpec, LibrarySpec) and an output location; output: trees/ and
views/ part files, _shards/ records, manifest.json.
Same spec and seed, same part-file bytes, whatever the number of workers or their finishing order.
"""
from __future__ import annotations

import contextlib
import json
import logging
import os
import resource
import shutil
import subprocess
import time
from dataclasses import dataclass
from typing import Callable

from renderers import FLOAT_OUTPUTS
from species.errors import TreefarmError
from species.timing import StageTimer

from .dataset import part_name, read_manifest, serialize_table, trees_schema, views_schema
from .jobs import PipelineSpec, species_of_trees
from .dataset.manifest import (JOB_RECORD, SHARDS_FOLDER, build_manifest, code_version, file_entry, finished_shards, read_shard_record,
                       write_job_record, write_manifest, write_shard_record)
from .ray_reaper import start_reaper
from .dataset.storage import Location, TransientWriteError
from .table import counted
from .tree_chain import (BuilderFactory, SpeciesChain, failed_tree_row, tree_row, tree_seed,
                         view_rows)

__all__ = ["ShardPlan", "plan_shards", "run_shard", "run_job", "ray_connection", "JobError", "WORKER_ENV",
           "ACTOR_RETRIES", "worker_env", "ShardWorker", "DEFAULT_MEMORY_SHARE", "worker_memory_bytes", "limit_memory"]

# Worker processes render offscreen through EGL (no display on farm machines).
WORKER_ENV = {"PYOPENGL_PLATFORM": "egl"}
# A worker that dies is restarted and its in-flight shard re-run this many times (Ray's own retries); so is a shard
# whose write failed for a reason that may pass. A permanent file error fails the job at once.
ACTOR_RETRIES = 3
# How often the driver reads the workers' per-tree progress while it waits for shards.
PROGRESS_SECONDS = 0.25


# Without `resources.memory_gb`, a worker limits itself to this share of its node's physical memory: one runaway
# tree then fails alone (MemoryError, a failed row) instead of taking the node down.
DEFAULT_MEMORY_SHARE = 0.5


def worker_memory_bytes(spec: PipelineSpec) -> int:
    """The memory limit of one worker: `resources.memory_gb`, or DEFAULT_MEMORY_SHARE of this node's memory."""
    if "memory_gb" in spec.resources:
        return int(spec.resources["memory_gb"] * 2**30)
    return int(DEFAULT_MEMORY_SHARE * os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))


def limit_memory(n_bytes: int) -> None:
    """Cap this process's data segment (heap and private writable mappings: what numpy and Python allocate) so
    that an allocation past it raises MemoryError. RLIMIT_DATA rather than RLIMIT_AS: the renderer's and
    Ray's threads reserve gigabytes of address space they never touch."""
    _, hard = resource.getrlimit(resource.RLIMIT_DATA)
    soft = n_bytes if hard == resource.RLIM_INFINITY else min(n_bytes, hard)
    resource.setrlimit(resource.RLIMIT_DATA, (soft, hard))


def _memory_note(exc: Exception) -> str:
    """What a MemoryError in a worker means, for the failed tree's row."""
    if not isinstance(exc, MemoryError):
        return ""
    soft, _ = resource.getrlimit(resource.RLIMIT_DATA)
    if soft == resource.RLIM_INFINITY:
        return ""
    return f" (over this worker's memory limit of {soft / 2**30:.1f} GiB: resources.memory_gb)"


def worker_env(spec: PipelineSpec) -> dict[str, str]:
    """Environment of a worker actor: EGL, and Mesa's rasterizer threads matched to the actor's CPUs
    (llvmpipe would otherwise start one thread per core in every actor and oversubscribe the machine)."""
    return {**WORKER_ENV, "LP_NUM_THREADS": str(max(1, int(spec.resources["num_cpus"])))}


class JobError(TreefarmError):
    """A job cannot run as asked (an output folder of another job, a shard that keeps failing)."""


@dataclass(frozen=True)
class ShardPlan:
    """Shard `shard` holds trees first_index .. first_index + n_trees - 1, of the given species."""

    shard: int
    first_index: int
    species: tuple[str, ...]

    @property
    def n_trees(self) -> int:
        return len(self.species)

    @property
    def indices(self) -> range:
        return range(self.first_index, self.first_index + self.n_trees)


def plan_shards(spec: PipelineSpec) -> list[ShardPlan]:
    """Fixed ranges of `spec.shard_size` trees (the last shard may be shorter)."""
    species = species_of_trees(spec)
    size = spec.shard_size
    return [ShardPlan(k, k * size, tuple(species[k * size:(k + 1) * size])) for k in range(spec.n_shards)]


def run_shard(spec: PipelineSpec, plan: ShardPlan, location: Location, builder, worker: dict | None = None,
              on_tree: Callable[[int], None] | None = None) -> dict:
    """Build every tree of a shard, write its two part files atomically, then its record; returns the record.

    worker : facts about the process to note in the record (the Ray node id).
    on_tree : called with the number of trees built so far in this shard, after each one (progress).
    A tree whose build raises becomes a row with its error (and a failure entry); the shard goes on.
    """
    shard_start, shard_cpu_start = time.perf_counter(), time.process_time()
    tree_rows, all_view_rows, failures, tree_timings = [], [], [], []
    for index, species_name in zip(plan.indices, plan.species):
        seed = tree_seed(spec.seed, index)
        timer = StageTimer()
        built = None
        try:
            built = builder(species_name, seed, timer)
            with timer.stage("encode"):
                row = tree_row(spec, index, plan.shard, species_name, seed, built)
                rows = view_rows(spec, index, plan.shard, built.views)
            tree_rows.append(row)
            all_view_rows.extend(rows)
        except Exception as exc:  # one bad tree is recorded (row + manifest failure) and the shard goes on
            message = f"{type(exc).__name__}: {exc}{_memory_note(exc)}"
            params = getattr(built, "params", None)
            tree_rows.append(failed_tree_row(spec, index, plan.shard, species_name, seed, params, message))
            failures.append({"tree_id": tree_rows[-1]["tree_id"], "index": index, "species": species_name,
                             "seed": seed, "stage": timer.current, "error": message})
        tree_timings.append({"index": index, **timer.seconds})
        if on_tree is not None:
            on_tree(len(tree_rows))
    start = time.perf_counter()
    trees_bytes = serialize_table(tree_rows, trees_schema())
    views_bytes = serialize_table(all_view_rows, views_schema(spec.tables.view_outputs, FLOAT_OUTPUTS))
    location.write_atomic(part_name("trees", plan.shard), trees_bytes)
    location.write_atomic(part_name("views", plan.shard), views_bytes)
    stages: dict[str, float] = {}
    for timing in tree_timings:
        for stage, seconds in timing.items():
            if stage != "index":
                stages[stage] = stages.get(stage, 0.0) + seconds
    stages["write"] = time.perf_counter() - start
    record = {"shard": plan.shard, "first_index": plan.first_index, "n_trees": plan.n_trees,
              "spec_digest": spec.digest(), "code_version": code_version(),
              "trees": file_entry("trees", plan.shard, trees_bytes, len(tree_rows)),
              "views": file_entry("views", plan.shard, views_bytes, len(all_view_rows)),
              "failures": failures, "timings": {"stages": stages, "trees": tree_timings,
                                                "wall_seconds": time.perf_counter() - shard_start,
                                                "cpu_seconds": time.process_time() - shard_cpu_start},
              "worker": {"pid": os.getpid(), "host": os.uname().nodename, **(worker or {})}}
    write_shard_record(location, record)
    return record


class ShardWorker:
    """A Ray actor: one tree builder (so one offscreen renderer) per process, taking shard tasks."""

    def __init__(self, spec: PipelineSpec, uri: str, builder_factory: BuilderFactory):
        import cv2

        cv2.setNumThreads(max(1, int(spec.resources["num_cpus"])))  # as LP_NUM_THREADS: one actor, its CPUs
        limit_memory(worker_memory_bytes(spec))
        self.spec, self.location = spec, Location.resolve(uri)
        # Made by the first task: Ray gives the driver an error raised in a task as itself, one raised in
        # __init__ only as the text of a dead actor.
        self.builder_factory, self.builder = builder_factory, None

    def run(self, plan: ShardPlan, progress=None) -> dict:
        """progress : a `ray.util.queue.Queue` that gets (shard, trees built so far) after each tree."""
        import ray

        if self.builder is None:
            self.builder = self.builder_factory(self.spec)
        on_tree = None if progress is None else (lambda built: progress.put_nowait((plan.shard, built)))
        return run_shard(self.spec, plan, self.location, self.builder,
                         worker={"node": ray.get_runtime_context().get_node_id()}, on_tree=on_tree)

    def pid(self) -> int:
        return os.getpid()


def _check_output_belongs_to(spec: PipelineSpec, location: Location) -> None:
    """Refuse to mix two jobs in one folder: the job record and every shard record must carry this spec's digest."""
    digest = spec.digest()
    digests = []
    if location.exists(JOB_RECORD):
        digests.append(json.loads(location.read_bytes(JOB_RECORD)).get("spec_digest"))
    for name in location.list(SHARDS_FOLDER):
        record = read_shard_record(location, int(name[5:10])) if name.startswith("part-") else None
        if record is not None:
            digests.append(record.get("spec_digest"))
    other = next((d for d in digests if d != digest), None)
    if other is not None:
        raise JobError(f"{location.uri} holds shards of another job spec (digest {str(other)[:12]}); "
                       f"write this job to another --out")


def _free_bytes(location: Location) -> int | None:
    """Free bytes of a local output's file system (of its nearest existing folder); None for object stores."""
    if not location.is_local:
        return None
    folder = location.root
    while not os.path.isdir(folder):
        folder = os.path.dirname(folder)
    return shutil.disk_usage(folder).free


def _check_free_space(location: Location, records: dict[int, dict], trees_left: int) -> None:
    """Refuse to go on when the output's free space cannot hold the trees left, at the bytes per tree of the
    shards this job has written so far (nothing is known before the first one)."""
    trees_done = sum(record["n_trees"] for record in records.values())
    free = _free_bytes(location) if trees_done and trees_left else None
    if free is None:
        return
    written = sum(record[table]["bytes"] for record in records.values() for table in ("trees", "views"))
    needed = written * trees_left // trees_done
    if needed > free:
        raise JobError(f"{location.uri} has {_mebibytes(free)} free; the {counted(trees_left, 'tree')} left need "
                       f"about {_mebibytes(needed)} (at the size of the {trees_done} written): free space there or "
                       f"resume into a larger --out")


def _mebibytes(n_bytes: int) -> str:
    return f"{n_bytes / 2**20:,.1f} MiB"


_RAY_TOKEN_LOGGER = "ray._private.authentication.authentication_token_setup"


def _quiet_local_token_warning(record: logging.LogRecord) -> bool:
    """Drop Ray's start-up line "Token authentication is enabled for this Ray cluster" (a logging filter)."""
    return not record.getMessage().startswith("Token authentication is enabled for this Ray cluster")


def _connect_ray(address: str | None, workers: int | None,
                 log_to_driver: bool = True) -> tuple[bool, subprocess.Popen | None]:
    """Start or join Ray unless this process already has: (whether we started it and must shut it down, the
    watchdog that ends a local Ray's processes with this one)."""
    import ray

    if ray.is_initialized():
        return False, None
    options = dict(include_dashboard=False, logging_level="WARNING", runtime_env={"env_vars": WORKER_ENV},
                   log_to_driver=log_to_driver)
    address = address or os.environ.get("RAY_ADDRESS")  # set inside a RayJob or by `ray job submit`
    if address is None:
        # "local": always a fresh Ray of our own, never a cluster some other process left running here.
        address = "local"
        options["num_cpus"] = max(os.cpu_count() or 1, workers or 1)
        # Its token guards a Ray only this process talks to; the README's cluster notes say what it means
        # where it matters (a cluster joined with --address, which keeps the warning).
        logging.getLogger(_RAY_TOKEN_LOGGER).addFilter(_quiet_local_token_warning)
    ray.init(address=address, **options)
    return True, start_reaper() if address == "local" else None


def _disconnect_ray(started_ray: bool, reaper: subprocess.Popen | None) -> None:
    import ray

    if started_ray:
        ray.shutdown()
    if reaper is not None:  # end of its pipe: it ends what ray.shutdown left running
        reaper.stdin.close()
        reaper.wait()


@contextlib.contextmanager
def ray_connection(address: str | None = None, workers: int | None = None, log_to_driver: bool = True):
    """Ray for a command's duration, as `run_job` connects it (joined at `address`, or a local Ray of this
    process's own whose processes end with it); `log_to_driver=False` keeps workers' log lines off the terminal
    (training: Ray Train reports every checkpoint)."""
    started_ray, reaper = _connect_ray(address, workers, log_to_driver)
    try:
        yield
    finally:
        _disconnect_ray(started_ray, reaper)


def _run_pending(spec: PipelineSpec, location: Location, pending: list[ShardPlan], records: dict[int, dict],
                 workers: int | None, builder_factory: BuilderFactory, bar) -> None:
    """Start the actors, keep each one busy with one shard at a time, collect the records as they land."""
    import ray
    from ray.util.queue import Queue

    memory = {"memory": worker_memory_bytes(spec)} if "memory_gb" in spec.resources else {}
    if workers is None:
        cluster = ray.cluster_resources()
        workers = int(cluster.get("CPU", 1) // max(spec.resources["num_cpus"], 1e-3))
        if memory:  # an actor Ray cannot place would hold its shard until the job ends
            workers = min(workers, int(cluster.get("memory", 0) // memory["memory"]))
        workers = max(1, workers)
    worker_class = ray.remote(ShardWorker).options(
        num_cpus=spec.resources["num_cpus"], num_gpus=spec.resources["num_gpus"], **memory,
        max_restarts=ACTOR_RETRIES, max_task_retries=ACTOR_RETRIES, runtime_env={"env_vars": worker_env(spec)})
    actors = [worker_class.remote(spec, location.uri, builder_factory) for _ in range(min(workers, len(pending)))]
    views_done = sum(record["views"]["rows"] for record in records.values())
    queue = list(reversed(pending))
    in_flight = {}
    # Trees built so far in each running shard, as the workers report them (only to a bar that is shown);
    # a re-run shard reports from 1 again.
    progress = None if bar.disable else Queue(actor_options={"num_cpus": 0})
    building: dict[int, int] = {}
    trees_finished = bar.n

    def submit(actor) -> None:
        if queue:
            plan = queue.pop()
            task = actor.run.options(retry_exceptions=[TransientWriteError]).remote(plan, progress)
            in_flight[task] = (actor, plan)

    def show_progress(redraw: bool = False) -> None:
        for shard, built in progress.get_nowait_batch(progress.qsize()) if progress is not None else ():
            if shard not in records:
                building[shard] = built
        shown = trees_finished + sum(building.values())
        if redraw or shown != bar.n:
            bar.n = shown
            bar.refresh()

    try:
        for actor in actors:
            submit(actor)
        while in_flight:
            ready, _ = ray.wait(list(in_flight), num_returns=1, timeout=PROGRESS_SECONDS)
            show_progress()
            if not ready:
                continue
            actor, plan = in_flight.pop(ready[0])
            try:
                record = ray.get(ready[0])
            except ray.exceptions.RayTaskError as exc:  # the task raised: a user's error as itself, a bug as is
                if isinstance(exc.cause, TreefarmError):
                    raise exc.cause from exc  # its one line; Ray's text (the worker's traceback) is its cause
                if isinstance(exc.cause, TransientWriteError):
                    raise JobError(f"shard {plan.shard} failed after {ACTOR_RETRIES} retries: "
                                   f"{exc.cause.strerror}") from exc
                raise
            except ray.exceptions.RayError as exc:  # the worker died and Ray's restarts and retries are exhausted
                raise JobError(f"shard {plan.shard} failed after {ACTOR_RETRIES} retries: "
                               f"{' '.join(str(exc).split())[:300]}") from exc
            records[plan.shard] = record
            building.pop(plan.shard, None)
            trees_finished += record["n_trees"]
            trees_left = sum(p.n_trees for p in queue) + sum(p.n_trees for _, p in in_flight.values())
            _check_free_space(location, records, trees_left)
            views_done += record["views"]["rows"]
            # A job without a views table (an asset library) has no view count to show.
            shown_views = {"views": views_done} if spec.tables.view_outputs else {}
            bar.set_postfix(**shown_views, failed=sum(len(r["failures"]) for r in records.values()), refresh=False)
            show_progress(redraw=True)
            submit(actor)
    finally:  # a failed shard or Ctrl-C ends the job: its actors must not go on holding their CPUs
        # Cancelled first, the shards still running are not retried (Ray would say so) when their actors die.
        for task in in_flight:
            ray.cancel(task)
        for actor in actors:
            ray.kill(actor)
        if progress is not None:
            progress.shutdown()


def run_job(spec: PipelineSpec, out: str, workers: int | None = None, address: str | None = None,
            builder_factory: BuilderFactory = SpeciesChain, progress: bool = True,
            on_resume: Callable[[int, int], None] | None = None) -> dict:
    """Run (or resume) a job into `out` and return its manifest.

    workers : actors to start (default: as many as the cluster's CPUs allow with the spec's num_cpus each).
    address : an existing Ray cluster (`ray://...` or `host:port`); default a local Ray started here.
    builder_factory : called once per actor with the spec; returns `builder(species, seed, timer) -> BuiltTree`.
    on_resume : called with (trees kept, trees of the job) before a job that kept finished shards goes on.
    """
    from tqdm import tqdm

    if workers is not None and workers < 1:
        raise JobError(f"--workers {workers} is invalid: allowed an integer >= 1")
    location = Location.resolve(out)
    plans = plan_shards(spec)
    _check_output_belongs_to(spec, location)
    for folder in ("trees", "views", SHARDS_FOLDER):
        location.remove_temporaries(folder)
    records = finished_shards(location, spec.digest(), len(plans))
    write_job_record(location, spec)
    pending = [plan for plan in plans if plan.shard not in records]
    if records and pending and on_resume is not None:
        on_resume(sum(record["n_trees"] for record in records.values()), spec.n_trees)
    started_ray, reaper, bar = False, None, None
    start = time.perf_counter()
    try:
        if pending:
            _check_free_space(location, records, sum(plan.n_trees for plan in pending))
            started_ray, reaper = _connect_ray(address, workers)
        # After Ray's start-up lines, so that none lands inside the bar.
        bar = tqdm(total=spec.n_trees, initial=sum(records[k]["n_trees"] for k in records), unit="tree",
                   desc=f"farm {spec.name}", disable=not progress, dynamic_ncols=True, smoothing=0.1)
        if pending:
            _run_pending(spec, location, pending, records, workers, builder_factory, bar)
        manifest_exists = location.exists("manifest.json")
        if pending or not manifest_exists:
            manifest = build_manifest(spec, records, time.perf_counter() - start)
            write_manifest(location, manifest)
        else:
            manifest = read_manifest(location)
    finally:
        if bar is not None:
            bar.close()
        _disconnect_ray(started_ray, reaper)
    return manifest
