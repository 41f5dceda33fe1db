"""Reliability of real jobs (the real species and renderer chain, all three generators, tiny settings):
killed workers and drivers, 1 vs 2 workers, damaged parts, bad specs, a multi-node Ray cluster on this machine."""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from functools import partial
from pathlib import Path

import pytest

import farm.dataset as dataset
from farm.cli import main as farm_main
from farm.jobs import parse_spec, spec_to_yaml
from farm.pipeline import run_job
from farm.tree_chain import SpeciesChain
from farm_standins import KillOnce

SPEC = {"name": "tiny", "seed": 3, "shard_size": 2,
        "species": {"maple": 2, "palm": 2, "sc_young_sapling": 2, "lsystem_fractal_plant": 2},
        "render": {"rig": "two-view", "size": 64}}
FARM = [sys.executable, "-m", "farm.cli"]


def part_bytes(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.glob("*/part-*.parquet"))}


@pytest.fixture(scope="module")
def spec_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("spec") / "tiny.yaml"
    path.write_text(spec_to_yaml(parse_spec(SPEC)))
    return path


@pytest.fixture(scope="module")
def reference(tmp_path_factory, ray_session):
    """An uninterrupted 2-worker run of the tiny job: (folder, part bytes)."""
    folder = tmp_path_factory.mktemp("reference")
    run_job(parse_spec(SPEC), str(folder), workers=2, progress=False)
    return folder, part_bytes(folder)


def test_reference_job_has_every_tree_once_with_meshes_and_views(reference):
    folder, parts = reference
    trees = dataset.to_pandas(str(folder), columns=["index", "error", "glb", "n_views"])
    assert sorted(trees["index"]) == list(range(8))
    assert trees["error"].isna().all() and trees["glb"].map(len).min() > 1000
    assert (trees["n_views"] == 2).all() and len(parts) == 8


def test_one_worker_writes_the_same_bytes_as_two(reference, tmp_path):
    run_job(parse_spec(SPEC), str(tmp_path), workers=1, progress=False)
    assert part_bytes(tmp_path) == reference[1]


def test_worker_killed_mid_job_is_restarted_and_the_result_is_unchanged(reference, tmp_path):
    flag = tmp_path / "killed"
    factory = partial(KillOnce, inner_factory=SpeciesChain, flag=str(flag), at_index=5)
    manifest = run_job(parse_spec(SPEC), str(tmp_path / "out"), workers=2, builder_factory=factory, progress=False)
    assert flag.exists()
    assert manifest["counts"] == {"trees": 8, "views": 16, "failed": 0, "shards": 4}
    assert part_bytes(tmp_path / "out") == reference[1]


def test_driver_killed_mid_job_resumes_to_identical_bytes(reference, spec_file, tmp_path):
    out = tmp_path / "out"
    driver = subprocess.Popen(FARM + ["generate", str(spec_file), "--out", str(out), "--workers", "1", "--quiet"],
                              start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not (out / "_shards/part-00000.json").exists():
        assert driver.poll() is None and time.monotonic() < deadline, "the driver ended before its first shard"
        time.sleep(0.02)
    os.killpg(driver.pid, signal.SIGKILL)  # the driver and the local Ray it started
    driver.wait()
    assert not (out / "manifest.json").exists()
    assert len(list((out / "_shards").glob("part-*.json"))) < 4
    run_job(parse_spec(SPEC), str(out), workers=2, progress=False)
    assert part_bytes(out) == reference[1]


def test_damaged_part_is_named_by_validate_and_regenerated_by_generate(reference, spec_file, tmp_path, capsys):
    out = tmp_path / "copy"
    shutil.copytree(reference[0], out)
    victim = out / "trees/part-00002.parquet"
    victim.write_bytes(victim.read_bytes()[:-100])
    assert farm_main(["validate", str(out)]) == 1
    assert str(victim) in capsys.readouterr().err
    assert farm_main(["generate", str(spec_file), "--out", str(out), "--quiet"]) == 0
    assert farm_main(["validate", str(out)]) == 0
    assert part_bytes(out) == reference[1]


@pytest.mark.parametrize("change, named", [
    ({"species": {"no_such_tree": 2}}, "species.no_such_tree"),
    ({"species": {"maple": -2}}, "species.maple"),
    ({"render": {"outputs": ["oil_painting"]}}, "render.outputs"),
])
def test_bad_spec_gives_a_one_line_error_and_writes_nothing(tmp_path, capsys, change, named):
    spec_path = tmp_path / "bad.yaml"
    import yaml

    spec_path.write_text(yaml.safe_dump({**SPEC, **change}))
    assert farm_main(["generate", str(spec_path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("farm: error:") and named in err[0]
    assert not (tmp_path / "out").exists()


def test_job_runs_across_a_two_node_ray_cluster(spec_file, tmp_path, reference):
    from ray.cluster_utils import Cluster

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    try:
        cluster.add_node(num_cpus=1)
        cluster.wait_for_nodes()
        out = tmp_path / "out"
        done = subprocess.run(FARM + ["generate", str(spec_file), "--out", str(out), "--workers", "2",
                                      "--address", cluster.address, "--quiet"], capture_output=True, text=True,
                              timeout=240)
        assert done.returncode == 0, done.stderr[-2000:]
    finally:
        cluster.shutdown()
    import json

    nodes = {json.loads(p.read_text())["worker"]["node"] for p in (out / "_shards").glob("part-*.json")}
    assert len(nodes) == 2
    assert part_bytes(out) == reference[1]


def test_status_reports_counts_and_stage_timings(reference, capsys):
    assert farm_main(["status", str(reference[0])]) == 0
    out = capsys.readouterr().out
    assert "trees 8  views 16  shards 4  failed 0" in out and "render" in out


def test_inspect_prints_a_species_table_and_writes_a_contact_sheet(reference, tmp_path, capsys):
    from PIL import Image

    png = tmp_path / "sheet.png"
    assert farm_main(["inspect", str(reference[0]), "--png", str(png), "--rows", "3"]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in SPEC["species"])
    width, height = Image.open(png).size
    assert width > height > 0  # 3 rows of 6 outputs


def test_the_inspect_contact_sheet_shows_the_silhouette_background_black_not_red(reference):
    from farm.commands.inspect import contact_rows
    from renderers.contact_sheet import to_rgb8

    columns = 0
    for _, cells in contact_rows(str(reference[0]), 2):
        for name, image in cells:
            if name == "silhouette":
                picture = to_rgb8(image)
                red = (picture[..., 0] > 0) & (picture[..., 1:] == 0).all(axis=2)
                assert (picture[0, 0] == 0).all() and not red.any()
                columns += 1
    assert columns == 2


def test_export_writes_the_stored_glb_of_every_tree_by_default_named_with_its_species(reference, tmp_path,
                                                                                     capsys):
    import trimesh

    out = tmp_path / "glb"
    assert farm_main(["export", str(reference[0]), "--out", str(out), "--quiet"]) == 0  # GLB unless told
    trees = dataset.to_pandas(str(reference[0]), columns=["tree_id", "species", "glb"])
    assert sorted(f.name for f in out.glob("*.glb")) == sorted(f"{row.species}-{row.tree_id}.glb"
                                                             for row in trees.itertuples())
    for row in trees.itertuples():
        assert (out / f"{row.species}-{row.tree_id}.glb").read_bytes() == row.glb
    assert len(trimesh.load(sorted(out.glob("*.glb"))[0], force="scene").geometry) >= 1
    size = sum(f.stat().st_size for f in out.glob("*.glb"))
    assert capsys.readouterr().out.strip().splitlines() == [
        f"{out}: 8 trees as glb (0 failed to generate, not exported), {size / 1e6:.1f} MB"]


def test_export_obj_rebuilds_each_tree_from_its_parameters(reference, tmp_path):
    assert farm_main(["export", str(reference[0]), "--format", "obj", "--out", str(tmp_path), "--quiet"]) == 0
    objs = sorted(tmp_path.glob("*/*.obj"))
    assert len(objs) == 8
    trees = dataset.to_pandas(str(reference[0]), columns=["tree_id", "species", "bark_triangles", "leaf_triangles"])
    faces = {f"{row.species}-{row.tree_id}": row.bark_triangles + row.leaf_triangles for row in trees.itertuples()}
    for obj in objs:
        assert sum(line.startswith("f ") for line in obj.read_text().splitlines()) == faces[obj.parent.name]


def test_export_still_reads_the_deprecated_to_and_says_so(reference, tmp_path, capsys):
    assert farm_main(["export", str(reference[0]), "--to", str(tmp_path), "--quiet"]) == 0
    assert len(list(tmp_path.glob("*.glb"))) == 8
    assert capsys.readouterr().err.strip() == "warning: --to is deprecated: use --out"


def test_export_rejects_an_unknown_format(reference, tmp_path, capsys):
    assert farm_main(["export", str(reference[0]), "--format", "fbx", "--out", str(tmp_path)]) == 2
    assert "allowed glb, obj" in capsys.readouterr().err


def test_generate_bar_holds_only_the_bar_and_ray_start_up_lines_stay_out_of_it(tmp_path):
    """The bar's per-tree steps are tested with slow stand-in trees (test_pipeline); here the real command."""
    spec = tmp_path / "two.yaml"
    spec.write_text(spec_to_yaml(parse_spec({"name": "two", "seed": 1, "shard_size": 2, "species": {"maple": 2},
                                             "render": {"rig": "two-view", "size": 64}})))
    done = subprocess.run(FARM + ["generate", str(spec), "--out", str(tmp_path / "out"), "--workers", "1"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "Token authentication" not in done.stderr
    frames = [frame.strip() for frame in done.stderr.replace("\r", "\n").splitlines() if frame.strip()]
    assert all(frame.startswith("farm two:") for frame in frames), frames
    assert "2/2" in frames[-1]
