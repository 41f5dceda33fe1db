"""The whole-command farm benchmark's breakdown: where a run's seconds went, from its manifest and shard records."""
import json

import pytest

from benchmarks.bench_farm_command import breakdown


def _job(folder, job_seconds, shards):
    (folder / "_shards").mkdir(parents=True)
    (folder / "manifest.json").write_text(json.dumps({"timings": {"wall_seconds": job_seconds}}))
    for index, (pid, seconds) in enumerate(shards):
        record = {"shard": index, "worker": {"pid": pid}, "timings": {"wall_seconds": seconds}}
        (folder / "_shards" / f"part-{index:05d}.json").write_text(json.dumps(record))


def test_the_serial_part_is_the_command_less_the_busiest_worker(tmp_path):
    _job(tmp_path, 10.0, [(1, 3.0), (2, 2.0), (1, 4.0), (2, 2.5)])
    run = breakdown(tmp_path, 12.0)
    assert run["busiest_worker"] == pytest.approx(7.0)
    assert run["shards_all_workers"] == pytest.approx(11.5)
    assert run["outside_job"] == pytest.approx(2.0)
    assert run["job_not_shards"] == pytest.approx(3.0)
    assert run["serial"] == pytest.approx(5.0)
    assert run["outside_job"] + run["job_not_shards"] + run["busiest_worker"] == pytest.approx(run["command"])
