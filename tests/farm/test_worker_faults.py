"""Faults in a job's workers and processes: permanent file errors fail at once with one line, transient ones are
retried; the output's free space is checked before a job writes; validate leaves no native thread running at exit."""
from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from ray import cloudpickle

from farm.pipeline import JobError, plan_shards, run_job, run_shard
from farm.dataset.storage import Location, TransientWriteError
from farm_standins import StandinChain, standin_spec
from species.errors import PathError

cloudpickle.register_pickle_by_value(sys.modules[__name__])  # the failing writers below run in Ray workers


class FailingMoves:
    """A file system whose renames of part files fail with `error_number` (each time, or until `flag` exists)."""

    def __init__(self, inner, error_number: int, flag: str | None):
        self.inner, self.error_number, self.flag = inner, error_number, flag

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def move(self, source: str, destination: str) -> None:
        if "/trees/part-" in destination and (self.flag is None or not os.path.exists(self.flag)):
            if self.flag is not None:
                Path(self.flag).write_text(destination)
            raise OSError(self.error_number, os.strerror(self.error_number))
        self.inner.move(source, destination)


def failing_moves(error_number: int, flag: str | None = None):
    """Make every Location of this process write through FailingMoves; returns the patch to undo."""
    real = Location.filesystem
    Location.filesystem = property(lambda location: FailingMoves(real.fget(location), error_number, flag))
    return real


class FailingWritesChain(StandinChain):
    """Stand-in trees from a worker whose part-file renames fail (made in the worker, so the patch is there)."""

    def __init__(self, spec, error_number: int, flag: str | None):
        super().__init__(spec)
        failing_moves(error_number, flag)


def test_no_space_is_a_path_error_naming_the_file_and_leaves_no_temporary(tmp_path):
    spec, location = standin_spec(), Location.resolve(str(tmp_path))
    real = failing_moves(errno.ENOSPC)
    try:
        with pytest.raises(PathError) as raised:
            run_shard(spec, plan_shards(spec)[0], location, StandinChain(spec))
    finally:
        Location.filesystem = real
    assert str(raised.value) == f"cannot write {tmp_path}/trees/part-00000.parquet: No space left on device"
    assert not list(tmp_path.rglob(f".tmp-*"))


def test_a_transient_write_error_is_raised_as_such(tmp_path):
    real = failing_moves(errno.EIO)
    try:
        with pytest.raises(TransientWriteError, match="trees/part-00000.parquet"):
            Location.resolve(str(tmp_path)).write_atomic("trees/part-00000.parquet", b"x")
    finally:
        Location.filesystem = real


def test_a_transient_write_error_in_a_worker_is_retried_to_the_same_bytes(tmp_path, ray_session):
    from functools import partial

    spec, flag = standin_spec(), tmp_path / "failed-once"
    run_job(spec, str(tmp_path / "clean"), workers=1, builder_factory=StandinChain, progress=False)
    factory = partial(FailingWritesChain, error_number=errno.EIO, flag=str(flag))
    run_job(spec, str(tmp_path / "out"), workers=1, builder_factory=factory, progress=False)
    assert flag.exists()
    parts = sorted(p.relative_to(tmp_path / "clean") for p in (tmp_path / "clean").glob("*/part-*.parquet"))
    assert all((tmp_path / "out" / p).read_bytes() == (tmp_path / "clean" / p).read_bytes() for p in parts)


def test_a_write_error_that_keeps_coming_back_ends_the_job_naming_the_file(tmp_path, ray_session):
    from functools import partial

    factory = partial(FailingWritesChain, error_number=errno.ETIMEDOUT, flag=None)
    with pytest.raises(JobError) as raised:
        run_job(standin_spec(), str(tmp_path), workers=1, builder_factory=factory, progress=False)
    assert str(raised.value) == (f"shard 0 failed after 3 retries: cannot write {tmp_path}/trees/part-00000.parquet: "
                                 f"{os.strerror(errno.ETIMEDOUT)}")


def test_a_part_path_that_is_a_folder_fails_the_job_at_once_naming_it_and_keeps_earlier_shards(tmp_path, ray_session):
    spec = standin_spec()
    out = tmp_path / "out"
    run_job(spec, str(out), workers=1, builder_factory=StandinChain, progress=False)
    kept = (out / "trees/part-00000.parquet").read_bytes()
    for name in ("manifest.json", "_shards/part-00001.json", "_shards/part-00002.json", "trees/part-00001.parquet"):
        (out / name).unlink()
    (out / "trees/part-00001.parquet").mkdir()  # the part's path: a folder no retry can write over
    with pytest.raises(PathError) as raised:
        run_job(spec, str(out), workers=1, builder_factory=StandinChain, progress=False)
    message = str(raised.value)
    assert len(message.splitlines()) == 1 and str(out / "trees/part-00001.parquet") in message
    assert "ShardWorker" not in message and "retries" not in message
    assert (out / "trees/part-00000.parquet").read_bytes() == kept


def finished_without_ray(folder: Path) -> Path:
    """A finished stand-in dataset written in this process (its shards run one after another, no Ray)."""
    from farm.dataset.manifest import build_manifest, write_job_record, write_manifest

    spec, location = standin_spec(), Location.resolve(str(folder))
    write_job_record(location, spec)
    records = {plan.shard: run_shard(spec, plan, location, StandinChain(spec)) for plan in plan_shards(spec)}
    write_manifest(location, build_manifest(spec, records, 0.0))
    return folder


def test_validate_starts_no_native_thread_that_could_outlive_the_interpreter(tmp_path):
    """`farm validate` printed ok and then aborted at exit: a thread of Arrow's pools torn down while alive.
    It must leave the process with the threads it had before it ran."""
    folder = finished_without_ray(tmp_path / "data")
    script = textwrap.dedent(f"""
        import os, pyarrow.parquet, farm.dataset.manifest
        from farm.cli import main
        before = len(os.listdir("/proc/self/task"))
        status = main(["validate", {str(folder)!r}])
        print(status, before, len(os.listdir("/proc/self/task")))
    """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    status, before, after = map(int, done.stdout.strip().splitlines()[-1].split())
    assert status == 0 and after == before


def test_a_job_stops_before_its_output_runs_out_of_space_and_says_how_much_it_needs(tmp_path, monkeypatch,
                                                                                      ray_session):
    import shutil

    import farm.pipeline

    spec, out = standin_spec(), tmp_path / "out"
    real = shutil.disk_usage
    monkeypatch.setattr(farm.pipeline.shutil, "disk_usage", lambda path: real(path)._replace(free=1000))
    with pytest.raises(JobError, match=r"has 0.0 MiB free; the 3 trees left need about [0-9.]+ MiB") as raised:
        run_job(spec, str(out), workers=1, builder_factory=StandinChain, progress=False)
    assert str(out) in str(raised.value)
    assert (out / "_shards/part-00000.json").exists() and (out / "trees/part-00000.parquet").exists()
    with pytest.raises(JobError, match="the 3 trees left"):  # a resume checks before it starts a worker
        run_job(spec, str(out), workers=1, builder_factory=StandinChain, progress=False)


def processes_of_session(session: int) -> list[str]:
    """`pid name` of every live process in the session `session` (a driver started with start_new_session)."""
    rows = subprocess.run(["ps", "-eo", "pid=,sid=,stat=,comm="], capture_output=True, text=True).stdout.splitlines()
    return [f"{r.split()[0]} {r.split()[3]}" for r in rows if r.split()[1] == str(session) and "Z" not in r.split()[2]]


def test_a_killed_driver_takes_the_local_ray_it_started_with_it(tmp_path):
    """SIGKILL to the driver alone (not its process group): Ray's agents used to outlive it."""
    out = tmp_path / "out"
    script = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        from ray import cloudpickle
        import farm_standins
        cloudpickle.register_pickle_by_value(farm_standins)
        from farm.pipeline import run_job
        spec = farm_standins.standin_spec(species={{"standin_a": 2000}})
        run_job(spec, {str(out)!r}, workers=1, builder_factory=farm_standins.StandinChain, progress=False)
    """)
    driver = subprocess.Popen([sys.executable, "-c", script], start_new_session=True, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not (out / "_shards/part-00000.json").exists():
        assert driver.poll() is None and time.monotonic() < deadline, "the driver ended before its first shard"
        time.sleep(0.05)
    assert len(processes_of_session(driver.pid)) > 3  # the driver, GCS, raylet, agents, a worker
    os.kill(driver.pid, signal.SIGKILL)
    driver.wait()
    deadline = time.monotonic() + 30
    while processes_of_session(driver.pid) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert processes_of_session(driver.pid) == []


def test_a_tree_over_the_worker_memory_limit_fails_alone_and_the_job_goes_on(tmp_path, ray_session):
    import farm.dataset as dataset

    spec = standin_spec(species={"standin_a": 2, "memory_hog": 1}, shard_size=3, resources={"memory_gb": 1})
    manifest = run_job(spec, str(tmp_path), workers=1, builder_factory=StandinChain, progress=False)
    assert manifest["counts"]["trees"] == 3 and manifest["counts"]["failed"] == 1
    trees = dataset.to_pandas(str(tmp_path), columns=["species", "error"]).set_index("species")
    assert trees.loc["memory_hog", "error"].startswith("MemoryError")
    assert "memory limit of 1.0 GiB: resources.memory_gb" in trees.loc["memory_hog", "error"]
    assert trees.loc["standin_a", "error"].isna().all()


def test_a_worker_limits_its_memory_to_the_spec_or_to_a_share_of_the_node(tmp_path):
    from farm.pipeline import DEFAULT_MEMORY_SHARE, worker_memory_bytes

    assert worker_memory_bytes(standin_spec(resources={"memory_gb": 2.5})) == int(2.5 * 2**30)
    node = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    assert worker_memory_bytes(standin_spec()) == int(DEFAULT_MEMORY_SHARE * node)


def test_a_job_whose_worker_was_killed_leaves_no_process_behind(tmp_path):
    """A worker SIGKILLed mid-shard is restarted by Ray; once the driver ends, nothing it started lives on."""
    out, flag = tmp_path / "out", tmp_path / "killed"
    script = textwrap.dedent(f"""
        import sys
        from functools import partial
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        from ray import cloudpickle
        import farm_standins
        cloudpickle.register_pickle_by_value(farm_standins)
        from farm.pipeline import run_job
        factory = partial(farm_standins.KillOnce, inner_factory=farm_standins.StandinChain, flag={str(flag)!r},
                          at_index=3)
        manifest = run_job(farm_standins.standin_spec(), {str(out)!r}, workers=2, builder_factory=factory,
                           progress=False)
        print("counts", manifest["counts"]["trees"], manifest["counts"]["failed"])
    """)
    driver = subprocess.Popen([sys.executable, "-c", script], start_new_session=True, stdout=subprocess.PIPE,
                              stderr=subprocess.DEVNULL, text=True)
    stdout, _ = driver.communicate(timeout=180)
    assert driver.returncode == 0 and "counts 5 0" in stdout.splitlines() and flag.exists()
    deadline = time.monotonic() + 30
    while processes_of_session(driver.pid) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert processes_of_session(driver.pid) == []
