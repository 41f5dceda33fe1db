"""`farm evaluate` as a user runs it: every method on the held-out trees of a small evaluation dataset (the shipped
models), real inputs, resume, failures, compare, and bad input (one line, exit status 2, nothing written)."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import duckdb
import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
import yaml
from PIL import Image

import species
from farm.cli import main
from farm.evaluate.job import ROWS, TREE_PICK, evaluation_data_spec, pick_across_species, plan_evaluation, serves
from farm.evaluate.methods import EvalSettings
from farm.evaluate.inputs import input_units
from farm.jobs import parse_spec
from farm.pipeline import run_job
from reconstruct.scoring import METRICS
from renderers import ViewRenderer
from trainers.data import split_part

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data"
METHODS = ["params", "sketch-depth", "two-view", "cloud"]
FAST = ["--sweep-step", "90", "--surface-samples", "2000", "--fit-evals", "2", "--workers", "2"]


@pytest.fixture(scope="module")
def eval_data(tmp_path_factory, ray_session):
    """The printed evaluation spec cut to three trees (a Weber-Penn maple and cherry, a colonization maple)."""
    raw = yaml.safe_load(evaluation_data_spec())
    raw.update(trees=3, species={"maple": 1, "sc_round_maple": 1, "cherry": 1}, shard_size=3)
    out = tmp_path_factory.mktemp("eval-data") / "data"
    run_job(parse_spec(raw), str(out), progress=False)
    return out


@pytest.fixture(scope="module")
def report(eval_data, tmp_path_factory):
    out = tmp_path_factory.mktemp("eval-report") / "report"
    code = main(["evaluate", "--data", str(eval_data), "--part", "all", "--methods", ",".join(METHODS),
                 "--out", str(out), *FAST])
    assert code == 0
    return out


def test_every_method_produces_rows_and_the_summary_has_every_method_and_metric(report):
    rows = pq.read_table(report / "metrics.parquet").to_pandas()
    assert sorted(rows["method"].unique()) == sorted(METHODS)
    assert (rows.groupby("method").size() == 3).all() and (rows["status"] == "ok").all()
    assert len(duckdb.sql(f"SELECT * FROM '{report / 'metrics.parquet'}'").fetchall()) == 12
    for column in ("silhouette_iou_unseen", "crown_iou_unseen", "node_hausdorff", "surface_chamfer",
                   "skeleton_f1_auc", "height_rel_error"):
        assert rows[column].notna().all(), column  # the geometry metrics apply to every method
    for column in rows.columns:
        if "iou" in column or column in ("skeleton_f1_auc", "cloud_fit_10cm", "joined_share"):
            values = rows[column].dropna()
            assert ((values >= 0) & (values <= 1)).all(), column
    by_method = rows.set_index("method")
    assert by_method.loc["sketch-depth", "depth_error_silhouette"].notna().all()
    assert by_method.loc["two-view", "main_skeleton_unit_cube_hausdorff"].notna().all()
    assert by_method.loc["cloud", "cloud_fit_10cm"].notna().all()
    assert by_method.loc["cloud", "depth_error_silhouette"].isna().all()  # what does not apply stays empty
    # Species accuracy only where the network can name the species (Weber-Penn presets).
    params = rows[rows["method"] == "params"].set_index("species")
    assert params.loc[["maple", "cherry"], "species_correct"].notna().all()
    assert np.isnan(params.loc["sc_round_maple", "species_correct"])
    assert (rows["seconds_unit"] > 0).all() and rows["seconds_total"].notna().any()
    assert json.loads(params.loc["maple", "models"])["sketchnet"].startswith("shipped default")

    summary = " ".join((report / "summary.md").read_text().split())
    for method in METHODS:
        assert f"{method} (all trees) 3 ok" in summary
    for metric in [m for m in METRICS if m in rows and rows[m].notna().any()]:
        assert METRICS[metric].label in summary, metric
    for figure in ("0.041", "0.032", "0.098", "~0.03 (TSN, 72 views"):  # the papers' figures beside ours
        assert figure in summary
    assert "sketchnet: shipped default" in summary and "score_overall" in summary and "## Made with" in summary

    sweep = pd.read_parquet(report / "sweep.parquet")
    assert list(sweep["azimuth_deg"]) == [0.0, 90.0, 180.0, 270.0] and (sweep["unit_cube_hausdorff"] > 0).all()
    for name in ("metrics_by_method.png", "metrics_by_species.png", "sweep.png",
                 *[f"gallery_{m}.png" for m in METHODS]):
        with Image.open(report / name) as image:
            assert image.width > 300 and image.height > 150, name
    for panel in rows["panel"]:
        with Image.open(report / panel) as image:
            assert image.width >= 3 * 192  # input, reconstruction, ground truth


def test_the_summary_fits_100_columns_and_says_held_out_only_of_held_out_trees(report):
    summary = (report / "summary.md").read_text()
    assert max(len(line) for line in summary.splitlines()) <= 100
    assert "held-out" not in summary.lower() and "held out" not in summary.lower()  # --part all: every tree
    assert "3 of 3 trees, 3 species: cherry 1, maple 1, sc_round_maple 1" in " ".join(summary.split())


def test_a_rerun_resumes_without_repeating_finished_trees(eval_data, report, tmp_path, capsys):
    copy = tmp_path / "report"
    shutil.copytree(report, copy)
    # A folder from before trees were picked across species: without --trees every tree is taken, so it resumes.
    job = json.loads((copy / "evaluation.json").read_text())
    assert job.pop("pick") == TREE_PICK
    (copy / "evaluation.json").write_text(json.dumps(job))
    removed = copy / ROWS / "cloud"
    victim = sorted(removed.glob("*.parquet"))[0]
    kept = {p: p.stat().st_mtime_ns for p in (copy / ROWS).glob("*/*.parquet") if p != victim}
    victim.unlink()
    capsys.readouterr()
    assert main(["evaluate", "--data", str(eval_data), "--part", "all", "--methods", ",".join(METHODS),
                 "--out", str(copy), *FAST]) == 0
    assert "11 from before" in capsys.readouterr().out
    assert victim.exists() and all(p.stat().st_mtime_ns == t for p, t in kept.items())
    # Another job into the same folder is refused, with nothing changed.
    assert main(["evaluate", "--data", str(eval_data), "--part", "all", "--methods", "cloud", "--out", str(copy),
                 *FAST]) == 2
    assert "holds another evaluation" in capsys.readouterr().err


def test_the_held_out_trees_are_the_trainers_test_split(eval_data):
    digest = json.loads((eval_data / "manifest.json").read_text())["spec_digest"]
    ids = [f"evaluation-{i:08d}" for i in range(3)]
    expected = [t for t in ids if split_part((digest, t)) == "test"]
    if expected:
        plan = plan_evaluation([str(eval_data)], ["cloud"], part="test")
        assert [u.tree_id for u in plan.units] == expected
    else:  # no test tree among three: the job says so in one line and writes nothing
        with pytest.raises(Exception, match="has no test \\(held-out\\) trees"):
            plan_evaluation([str(eval_data)], ["cloud"], part="test")
    plan = plan_evaluation([str(eval_data)], ["cloud", "params"], part="all", trees=2)
    species_of = {r["tree_id"]: r["species"]
                  for r in pq.read_table(eval_data / "trees", columns=["tree_id", "species"]).to_pylist()}
    chosen = [u.tree_id for u in plan.units if u.method == "cloud"]
    assert [u.tree_id for u in plan.units if u.method == "params"] == chosen == sorted(chosen)
    assert len({species_of[t] for t in chosen}) == 2  # two trees, two species
    assert plan.picked == {str(eval_data): {species_of[t]: 1 for t in chosen}}


def test_trees_are_picked_across_species_of_an_interleaved_dataset():
    # Eight species interleaved as a job plans them, three trees each: spreading 4 picks evenly over the list fell
    # on two species (issue 48); picked across species, 4 trees are 4 species and 8 are all 8.
    names = [f"species_{k}" for k in range(8)]
    trees = [f"tree-{i:02d}" for i in range(24)]
    species_of = dict(zip(trees, [names[i % 8] for i in range(24)]))
    for n in (4, 8, 11):
        chosen = pick_across_species(trees, [species_of[t] for t in trees], n)
        assert len(chosen) == n and chosen == sorted(chosen)
        counts = [sum(species_of[t] == name for t in chosen) for name in names]
        assert sum(c > 0 for c in counts) == min(n, 8) and max(counts) - min(counts) <= 1
    uneven = ["a"] * 6 + ["b"]  # a species with one tree gives its one; the rest go to the other, spread out
    assert pick_across_species(list("0123456"), uneven, 3) == ["0", "5", "6"]
    assert pick_across_species(trees, [species_of[t] for t in trees], None) == trees


def test_a_report_of_trees_picked_the_old_way_is_not_resumed_with_new_picks(eval_data, tmp_path, capsys):
    out = tmp_path / "report"
    plan = plan_evaluation([str(eval_data)], ["cloud"], part="all", trees=2,
                           settings=EvalSettings(surface_samples=2000, fit_evals=2))  # FAST's
    old = {k: v for k, v in plan.record.items() if k != "pick"}
    out.mkdir()
    (out / "evaluation.json").write_text(json.dumps(old, indent=1, sort_keys=True))
    capsys.readouterr()
    assert main(["evaluate", "--data", str(eval_data), "--part", "all", "--methods", "cloud", "--trees", "2",
                 "--out", str(out), *FAST]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("farm: error: ") and "picked another way" in err and len(err.splitlines()) == 1
    assert sorted(p.name for p in out.iterdir()) == ["evaluation.json"]


def test_a_method_a_dataset_cannot_serve_is_skipped_with_the_reason():
    pairs, why = serves("two-view", "tsn4+two-view:shared", ["sketch_tsn", "sketch_strokes"])
    assert pairs == (("front", "two-view:shared/front"), ("side", "two-view:shared/side")) and why == ""
    assert serves("params", "tsn4", ["sketch_tsn"])[0] == (("front", "front"),)
    pairs, why = serves("sketch-depth", "two-view", ["sketch_edges", "silhouette_envelope"])
    assert pairs is None and "lack trunk_strokes" in why
    pairs, why = serves("params", "two-view:jitter", ["sketch_tsn"])
    assert pairs is None and "has no 'tsn4' views" in why
    assert serves("cloud", "two-view", [])[0] == ()


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """Real inputs: the shared tree1 scan, a cloud too small to be a tree, a TreeSketchNet-style sketch of an
    unseen cherry with its reference dictionary, and the same sketch alone."""
    folder = tmp_path_factory.mktemp("inputs")
    shutil.copy(SHARED / "pointclouds" / "tree1.xyz", folder / "tree1.xyz")
    (folder / "broken.xyz").write_text("0 0 0\n1 1 1\n")
    params = species.sample("cherry", np.random.default_rng(31))
    skeleton, mesh = species.rebuild(params)
    renderer = ViewRenderer(224)
    try:
        view = renderer.render(mesh, skeleton, "tsn4", ["sketch_tsn"], np.random.default_rng(0))[0]
    finally:
        renderer.close()
    for name in ("cherry", "unlabelled"):
        Image.fromarray(view.images["sketch_tsn"]).save(folder / f"{name}.png")
    (folder / "cherry.json").write_text(json.dumps(params))
    return folder


def test_real_inputs_are_scored_and_a_failing_one_is_recorded_while_the_job_goes_on(inputs, tmp_path, capsys):
    out = tmp_path / "report"
    assert main(["evaluate", "--inputs", str(inputs), "--methods", "cloud,params", "--out", str(out), *FAST]) == 0
    rows = pd.read_parquet(out / "metrics.parquet").set_index("tree_id")
    rows.index = [Path(i).name for i in rows.index]
    assert sorted(rows.index) == ["broken.xyz", "cherry.png", "tree1.xyz", "unlabelled.png"]
    assert rows.loc["broken.xyz", "status"] == "failed" and "point" in rows.loc["broken.xyz", "error"]
    tree1 = rows.loc["tree1.xyz"]
    assert tree1["status"] == "ok" and tree1["cloud_fit_10cm"] > 0.9  # docs: 96.9 % within 10 cm
    assert tree1["bark_height_rel_error"] < 0.05 and tree1["joined_share"] > 0.95
    cherry = rows.loc["cherry.png"]
    assert cherry["species"] == "cherry" and cherry["species_correct"] in (0.0, 1.0)
    assert 0 < cherry["param_score"] <= 100 and np.isnan(cherry["silhouette_iou_input"])
    unlabelled = rows.loc["unlabelled.png"]
    assert 0.3 < unlabelled["silhouette_iou_input"] <= 1 and np.isnan(unlabelled["param_score"])
    summary = " ".join((out / "summary.md").read_text().split())
    assert "cloud (real inputs) 1 ok" in summary and "## Failures" in summary and "broken.xyz" in summary


def test_drawings_with_an_alpha_channel_are_scored_like_the_same_drawing_on_paper(inputs, tmp_path):
    """RGBA drawings on a transparent background (as drawing programs save them): the rendered sketch as black ink
    whose alpha is its darkness, and a real hand drawing where present; each gives a row with no error."""
    folder = tmp_path / "drawings"
    folder.mkdir()
    grey = np.asarray(Image.open(inputs / "unlabelled.png").convert("L"))
    ink = np.dstack([np.zeros(grey.shape + (3,), np.uint8), 255 - grey])  # transparent black paper
    Image.fromarray(ink, "RGBA").save(folder / "transparent.png")
    real = SHARED / "sketches" / "mouse_branches_foliage" / "sketch__v2.png"
    if real.exists():
        shutil.copy(real, folder / "hand.png")
    out = tmp_path / "report"
    assert main(["evaluate", "--inputs", str(folder), "--methods", "params", "--out", str(out), *FAST]) == 0
    rows = pd.read_parquet(out / "metrics.parquet").set_index("tree_id")
    rows.index = [Path(i).name for i in rows.index]
    assert sorted(rows.index) == (["hand.png"] if real.exists() else []) + ["transparent.png"]
    assert (rows["status"] == "ok").all(), rows["error"].tolist()
    assert 0.3 < rows.loc["transparent.png", "silhouette_iou_input"] <= 1  # as the same sketch on paper
    assert (rows["silhouette_iou_input"] > 0).all()


def test_compare_reports_a_known_change_and_gates_on_it(report, tmp_path, capsys):
    better = tmp_path / "b"
    better.mkdir()
    rows = pd.read_parquet(report / "metrics.parquet")
    rows.loc[rows["method"] == "cloud", "cloud_fit_10cm"] -= 0.2
    rows.loc[rows["method"] == "params", "node_hausdorff"] -= 0.05
    rows.to_parquet(better / "metrics.parquet", index=False)
    capsys.readouterr()
    assert main(["evaluate", "compare", str(report), str(better)]) == 0
    table = capsys.readouterr().out
    line = next(x for x in table.splitlines() if x.startswith("cloud") and "within 10 cm" in x)
    assert "-0.2000" in line and line.rstrip().endswith("worse")
    line = next(x for x in table.splitlines() if x.startswith("params") and "node Hausdorff / height" in x)
    assert "-0.0500" in line and line.rstrip().endswith("better")
    assert main(["evaluate", "compare", str(report), str(better), "--fail-if-worse", "cloud_fit_10cm:0.1"]) == 1
    assert "worse: cloud cloud_fit_10cm" in capsys.readouterr().err
    assert main(["evaluate", "compare", str(report), str(better), "--fail-if-worse", "cloud_fit_10cm:0.25",
                 "--fail-if-worse", "node_hausdorff"]) == 0
    assert main(["evaluate", "compare", str(report), str(better), "--fail-if-worse", "all"]) == 1
    capsys.readouterr()
    assert main(["evaluate", "compare", str(report), str(better), "--fail-if-worse", "sharpness"]) == 2
    assert capsys.readouterr().err.startswith("farm: error: --fail-if-worse sharpness: unknown metric")


@pytest.mark.parametrize("argv, message", [
    (["--methods", "params,lidar"], "unknown lidar"),
    (["--methods", "params", "--models", "{empty}"], "has no version in the model registry"),
    (["--methods", "params", "--models", "{nothing}"], "holds no model registry"),
    (["--methods", "cloud", "--part", "test", "--data", "{empty_data}"], "has no test (held-out) trees"),
    (["--methods", "cloud", "--trees", "0"], "--trees 0 is invalid"),
])
def test_bad_input_is_one_line_exit_2_and_nothing_written(eval_data, tmp_path, capsys, argv, message):
    from trainers.registry import open_registry

    open_registry(tmp_path / "empty")
    (tmp_path / "nothing").mkdir()
    empty_data = tmp_path / "empty_data"
    shutil.copytree(eval_data, empty_data)
    for part in (empty_data / "trees").glob("*.parquet"):  # every tree failed: nothing to evaluate
        table = pq.read_table(part).to_pandas()
        table["error"] = "failed on purpose"
        table.to_parquet(part, index=False)
    argv = [a.format(empty=tmp_path / "empty", nothing=tmp_path / "nothing", empty_data=empty_data) for a in argv]
    if "--data" not in argv:
        argv += ["--data", str(eval_data), "--part", "all"]
    out = tmp_path / "report"
    assert main(["evaluate", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("farm: error: ") and message in err and len(err.splitlines()) == 1
    assert not out.exists() and not (tmp_path / "nothing" / "mlflow.sqlite").exists()


def test_inputs_take_sketches_of_every_image_kind_the_reader_reads(tmp_path):
    for name in ("a.png", "b.jpg", "c.JPEG", "d.tif", "e.webp", "notes.md"):
        (tmp_path / name).write_bytes(b"")
    units, skipped = input_units(str(tmp_path), ["params"])
    assert [Path(u.tree_id).name for u in units] == ["a.png", "b.jpg", "c.JPEG", "d.tif", "e.webp"] and not skipped


def test_eval_settings_are_part_of_the_job_record(eval_data):
    a = plan_evaluation([str(eval_data)], ["cloud"], part="all", settings=EvalSettings(surface_samples=10))
    b = plan_evaluation([str(eval_data)], ["cloud"], part="all", settings=EvalSettings(surface_samples=20))
    assert a.record != b.record and a.record["settings"]["surface_samples"] == 10


@pytest.mark.slow
def test_the_photos_method_renders_an_orbit_and_scores_the_sfm_tree_in_the_true_frame(eval_data, tmp_path):
    out = tmp_path / "report"
    assert main(["evaluate", "--data", str(eval_data), "--part", "all", "--trees", "1", "--methods", "photos",
                 "--out", str(out), "--sweep-step", "0", "--surface-samples", "2000"]) == 0
    row = pd.read_parquet(out / "metrics.parquet").iloc[0]
    assert row["status"] == "ok" and row["method"] == "photos"
    # Known poses give metres in the renders' world: the SfM tree stands where the true one does, about as tall
    # (sparse SfM: docs/reconstruct.md measures -10 % on an oak).
    assert row["height_rel_error"] < 0.3 and row["node_chamfer"] < 0.3
    assert 0 < row["cloud_fit_10cm"] <= 1 and row["seconds_photos__cycles"] > 0 and row["seconds_sfm_features"] > 0
