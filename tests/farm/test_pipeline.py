"""The pipeline with stand-in builders: seeds, plan, shard writing, determinism across workers, resume, repair."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

import farm.dataset as dataset
from farm.dataset.manifest import validate_dataset
from farm.pipeline import JobError, plan_shards, run_job, run_shard
from farm.dataset.storage import Location
from farm.tree_chain import tree_seed
from farm_standins import SlowChain, StandinChain, standin_spec


def part_bytes(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.glob("*/part-*.parquet"))}


def test_tree_seed_comes_from_the_spawned_seed_sequence_and_not_from_the_job_size():
    children = np.random.SeedSequence(11).spawn(5)
    expected = [int(c.generate_state(1, np.uint64)[0] >> np.uint64(1)) for c in children]
    assert [tree_seed(11, i) for i in range(5)] == expected
    assert len(set(expected)) == 5


def test_shards_hold_fixed_ranges_covering_every_tree_once():
    spec = standin_spec(species={"standin_a": 4, "standin_b": 3}, shard_size=3)
    plans = plan_shards(spec)
    assert [p.n_trees for p in plans] == [3, 3, 1]
    assert [i for p in plans for i in p.indices] == list(range(7))


def test_run_shard_writes_both_parts_and_a_record_with_checksums(tmp_path):
    spec = standin_spec()
    record = run_shard(spec, plan_shards(spec)[1], Location.resolve(str(tmp_path)), StandinChain(spec))
    trees = pq.read_table(tmp_path / "trees/part-00001.parquet")
    views = pq.read_table(tmp_path / "views/part-00001.parquet")
    assert trees["index"].to_pylist() == [2, 3]
    assert trees["tree_id"].to_pylist() == ["standin-00000002", "standin-00000003"]
    assert views.num_rows == 4 and record["views"]["rows"] == 4
    assert json.loads((tmp_path / "_shards/part-00001.json").read_text())["trees"]["sha256"] == record["trees"]["sha256"]
    assert not [p for p in tmp_path.rglob(".tmp-*")]


def test_failed_tree_is_recorded_with_seed_and_message_and_the_shard_goes_on(tmp_path):
    spec = standin_spec(species={"standin_a": 1, "broken": 1})
    record = run_shard(spec, plan_shards(spec)[0], Location.resolve(str(tmp_path)), StandinChain(spec))
    (failure,) = record["failures"]
    assert failure["seed"] == tree_seed(spec.seed, failure["index"])
    assert failure["stage"] == "grow" and "refuses species 'broken'" in failure["error"]
    trees = pq.read_table(tmp_path / "trees/part-00000.parquet").to_pylist()
    assert [t["error"] is None for t in trees].count(True) == 1
    assert record["views"]["rows"] == 2


@pytest.fixture(scope="module")
def finished(tmp_path_factory, ray_session):
    """A finished 1-worker stand-in job: (spec, folder, part bytes)."""
    spec = standin_spec()
    folder = tmp_path_factory.mktemp("finished")
    run_job(spec, str(folder), workers=1, builder_factory=StandinChain, progress=False)
    return spec, folder, part_bytes(folder)


def copy_of(finished, tmp_path) -> Path:
    shutil.copytree(finished[1], tmp_path / "copy")
    return tmp_path / "copy"


def test_two_workers_write_the_same_bytes_as_one(finished, tmp_path):
    spec, _, one = finished
    run_job(spec, str(tmp_path), workers=2, builder_factory=StandinChain, progress=False)
    assert len(one) == 2 * spec.n_shards and part_bytes(tmp_path) == one


def test_rerun_skips_finished_shards(finished, tmp_path):
    spec, folder = finished[0], copy_of(finished, tmp_path)
    stamps = {p: p.stat().st_mtime_ns for p in folder.glob("*/part-*")}
    manifest = run_job(spec, str(folder), workers=2, builder_factory=StandinChain, progress=False)
    assert {p: p.stat().st_mtime_ns for p in folder.glob("*/part-*")} == stamps
    assert manifest["counts"]["trees"] == spec.n_trees


@pytest.mark.parametrize("damage", ["corrupt", "truncate", "delete"])
def test_damaged_part_is_named_by_validate_and_regenerated_by_the_next_run(finished, tmp_path, damage):
    spec, folder = finished[0], copy_of(finished, tmp_path)
    victim = folder / "views/part-00001.parquet"
    data = victim.read_bytes()
    if damage == "corrupt":
        victim.write_bytes(data[:100] + bytes([data[100] ^ 0xFF]) + data[101:])
    elif damage == "truncate":
        victim.write_bytes(data[: len(data) // 2])
    else:
        victim.unlink()
    problems = validate_dataset(str(folder))
    assert [p.path for p in problems] == [str(victim)]
    run_job(spec, str(folder), workers=1, builder_factory=StandinChain, progress=False)
    assert validate_dataset(str(folder)) == []
    assert part_bytes(folder) == finished[2]


def farm_generate(spec, out: Path, monkeypatch) -> int:
    """`farm generate --out OUT --quiet` on a stand-in spec and builder."""
    from functools import partial

    import farm.pipeline
    from farm.cli import main
    from farm.commands import generate as generate_command

    monkeypatch.setattr(generate_command, "load_job", lambda args: spec)
    monkeypatch.setattr(farm.pipeline, "run_job", partial(run_job, builder_factory=StandinChain))
    return main(["generate", "--out", str(out), "--quiet"])


def test_generate_rerun_of_a_finished_job_reports_this_run_s_seconds(finished, tmp_path, monkeypatch, capsys):
    spec, folder = finished[0], copy_of(finished, tmp_path)
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["timings"]["wall_seconds"] = 27.6  # the run that finished the job was a long one
    (folder / "manifest.json").write_text(json.dumps(manifest))
    assert farm_generate(spec, folder, monkeypatch) == 0
    (line,) = capsys.readouterr().out.splitlines()
    seconds = float(line.rsplit(";", 1)[1].split()[0])
    assert line.endswith(" s this run") and seconds < 20


def test_generate_resume_says_how_many_trees_it_kept(finished, tmp_path, monkeypatch, capsys):
    spec, folder = finished[0], copy_of(finished, tmp_path)
    (folder / "manifest.json").unlink()
    (folder / "_shards/part-00001.json").unlink()  # shard 1 (2 of the 5 trees) is built again
    assert farm_generate(spec, folder, monkeypatch) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"{folder}: resuming: 3 of 5 trees kept"
    assert lines[1].startswith(f"{folder}: 5 trees (0 failed), 10 views in 3 shards; ")


def test_generate_counts_one_of_a_kind_in_the_singular(tmp_path, monkeypatch, capsys, ray_session):
    spec = standin_spec(species={"standin_a": 1})
    assert farm_generate(spec, tmp_path / "one", monkeypatch) == 0
    assert f"{tmp_path / 'one'}: 1 tree (0 failed), 2 views in 1 shard; " in capsys.readouterr().out


def test_output_folder_of_another_spec_is_refused(finished, tmp_path):
    folder = copy_of(finished, tmp_path)
    with pytest.raises(JobError, match="another job spec"):
        run_job(standin_spec(seed=99), str(folder), workers=1, builder_factory=StandinChain, progress=False)
    assert not list(folder.rglob(".tmp-*"))


def test_killed_worker_shard_is_retried_and_every_tree_is_present_once(tmp_path, ray_session):
    from functools import partial

    from farm_standins import KillOnce

    spec = standin_spec()
    flag = tmp_path / "killed"
    factory = partial(KillOnce, inner_factory=StandinChain, flag=str(flag), at_index=3)
    manifest = run_job(spec, str(tmp_path / "out"), workers=2, builder_factory=factory, progress=False)
    assert flag.exists()  # a worker process really died mid-shard
    ids = dataset.to_pandas(str(tmp_path / "out"), columns=["index"])["index"].tolist()
    assert sorted(ids) == list(range(spec.n_trees))
    assert manifest["counts"]["failed"] == 0


def test_tree_over_the_node_limit_is_recorded_as_failed_before_meshing(tmp_path):
    from farm.jobs import parse_spec
    from farm.tree_chain import SpeciesChain

    spec = parse_spec({"name": "limit", "species": {"maple": 1}, "max_nodes": 10,
                       "render": {"rig": "two-view", "size": 32}})
    record = run_shard(spec, plan_shards(spec)[0], Location.resolve(str(tmp_path)), SpeciesChain(spec))
    (failure,) = record["failures"]
    assert failure["stage"] == "grow" and "max_nodes = 10" in failure["error"]
    assert "mesh" not in record["timings"]["trees"][0]


def test_job_writes_to_a_filesystem_uri_and_reads_back(finished, tmp_path):
    spec = finished[0]
    uri = f"file://{tmp_path}/by-uri"
    manifest = run_job(spec, uri, workers=1, builder_factory=StandinChain, progress=False)
    assert manifest["counts"]["trees"] == spec.n_trees
    assert part_bytes(tmp_path / "by-uri") == finished[2]
    assert dataset.to_pandas(uri, columns=["tree_id"])["tree_id"].is_unique
    assert validate_dataset(uri) == []



def test_the_progress_bar_advances_per_tree_while_a_shard_runs(tmp_path, monkeypatch, ray_session):
    import tqdm

    shown = []

    class RecordingBar(tqdm.tqdm):
        def refresh(self, *args, **kwargs):
            shown.append(self.n)
            return super().refresh(*args, **kwargs)

    monkeypatch.setattr(tqdm, "tqdm", RecordingBar)
    spec = standin_spec(species={"standin_a": 4}, shard_size=4)
    run_job(spec, str(tmp_path), workers=1, builder_factory=SlowChain, progress=True)
    assert shown == sorted(shown) and shown[-1] == 4
    assert {1, 2, 3} <= set(shown)  # one shard: the bar moved before the shard was written


def test_an_interrupted_job_ends_its_shards_without_ray_saying_they_will_be_retried(tmp_path, monkeypatch, capfd,
                                                                                     ray_session):
    import time

    import tqdm

    class InterruptedBar(tqdm.tqdm):
        """Ctrl-C as the first tree lands, while both workers are building."""

        def refresh(self, *args, **kwargs):
            if self.n >= 1:
                raise KeyboardInterrupt
            return super().refresh(*args, **kwargs)

    monkeypatch.setattr(tqdm, "tqdm", InterruptedBar)
    spec = standin_spec(species={"standin_a": 8}, shard_size=4)
    with pytest.raises(KeyboardInterrupt):
        run_job(spec, str(tmp_path), workers=2, builder_factory=SlowChain, progress=True)
    time.sleep(3)  # Ray reports a killed actor's task to the driver a moment later
    captured = capfd.readouterr()
    assert "will be retried" not in captured.out + captured.err


def test_status_and_validate_count_one_of_a_kind_in_the_singular(tmp_path, capsys, ray_session):
    from farm.cli import main

    run_job(standin_spec(species={"standin_a": 1}), str(tmp_path), workers=1, builder_factory=StandinChain,
            progress=False)
    assert main(["validate", str(tmp_path)]) == 0
    assert capsys.readouterr().out == f"{tmp_path}: ok, 2 part files match the manifest (1 tree, 2 views)\n"
    (tmp_path / "manifest.json").unlink()
    assert main(["status", str(tmp_path)]) == 0
    assert f"unfinished job 'standin': 1 of 1 shard, 1 of 1 tree written" in capsys.readouterr().out
