"""trainers.tasks and trainers.data: the shipped data specs, dataset checks, the split by tree, rejections, loaders.

Tiny versions of the three shipped specs (2-3 trees, 64 px) are generated once per module on the shared Ray.
"""
from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

from farm.jobs import load_spec, parse_spec
from farm.pipeline import run_job
from farm.review.export import export_reviews
from farm.review.store import ReviewStore
from trainers.data import PARTS, Split, TaskDataset, open_data, rejected_trees, split_part, to_ray_dataset
from trainers.preprocess import KINDS, preprocess
from trainers.tasks import TASKS, MissingOutputError, TrainingDataError, print_data_spec

torch.set_num_threads(1)
VIEWS_PER_TREE = {"tsn4": 4, "two-view": 2, "orbit": 8}


def _tiny(name: str, trees: int, seed: int | None = None):
    spec = load_spec(TASKS[name].spec_path).with_trees(trees)
    return dataclasses.replace(spec, render=dataclasses.replace(spec.render, size=64), shard_size=2,
                               seed=spec.seed if seed is None else seed)


@pytest.fixture(scope="module")
def datasets(tmp_path_factory, ray_session) -> dict[str, Path]:
    """Task name -> a finished tiny dataset of its shipped spec; "sketchnet-b": a second sketchnet job (same tree
    ids, another seed, so another spec digest)."""
    root = tmp_path_factory.mktemp("trainers-data")
    jobs = {"sketchnet": _tiny("sketchnet", 3), "pix2pix-silhouette": _tiny("pix2pix-silhouette", 2),
            "pix2pix-trunk": _tiny("pix2pix-trunk", 2), "sketchnet-b": _tiny("sketchnet", 2, seed=99),
            "tree-mask": _tiny("tree-mask", 1)}
    out = {}
    for name, spec in jobs.items():
        out[name] = root / name
        run_job(spec, str(out[name]), workers=2, progress=False)
    return out


# ------------------------------------------------------------------------------------------ specs and tasks
@pytest.mark.parametrize("name", list(TASKS))
def test_shipped_spec_loads_and_makes_a_few_thousand_views(name):
    task = TASKS[name]
    spec = load_spec(task.spec_path)
    assert set(task.required_outputs) <= set(spec.render.outputs)
    assert spec.render.size == task.input_size
    rig = spec.render.rig.split(":")[0]
    assert not task.rigs or rig in task.rigs
    assert 2000 <= spec.n_trees * VIEWS_PER_TREE[rig] <= 10000
    # The printed spec is the file, and reads back to the same job.
    text = print_data_spec(name)
    assert text == task.spec_path.read_text()
    assert parse_spec(yaml.safe_load(text)).digest() == spec.digest()


def test_sketchnet_spec_covers_the_weber_penn_presets():
    import species

    spec = load_spec(TASKS["sketchnet"].spec_path)
    wanted = {p.name for p in species.list_presets() if p.generator == "weber_penn"}
    assert set(spec.species) == wanted and spec.render.rig == "tsn4"


@pytest.mark.parametrize("name", list(TASKS))
def test_tiny_run_of_each_spec_holds_what_its_task_needs(datasets, name):
    task = TASKS[name]
    manifest = task.check_dataset(str(datasets[name]))
    assert manifest["counts"]["failed"] == 0
    data = open_data(name, [str(datasets[name])])
    dataset = TaskDataset(data, Split.by_hash(data.keys, (1.0, 0.0, 0.0)), "train")
    assert len(dataset) == manifest["counts"]["views"]
    item = dataset[0]
    channels = KINDS[task.input_kind]
    assert item["input"].shape == (channels, task.input_size, task.input_size)
    assert item["input"].dtype == torch.float32 and 0 <= item["input"].min() and item["input"].max() <= 1
    if name == "sketchnet":
        assert json.loads(item["params_json"])["species"] == item["species"]
    else:
        out_channels = {"pix2pix-silhouette": 3, "pix2pix-trunk": 1, "tree-mask": 1}[name]
        assert item["target"].shape == (out_channels, task.input_size, task.input_size)
        assert item["mask"].shape == (1, task.input_size, task.input_size)
        # pix2pix's loss mask is the foreground; the tree mask network's loss covers every pixel, its target the tree
        covered = item["target"] if task.network == "segment" else item["mask"]
        assert 0 < covered.mean() < 1


def test_missing_output_names_the_output_and_the_spec(datasets):
    with pytest.raises(MissingOutputError) as caught:
        TASKS["pix2pix-trunk"].check_dataset(str(datasets["sketchnet"]))
    message = str(caught.value)
    assert "'trunk_strokes'" in message and "pix2pix-trunk.yaml" in message
    assert "farm train pix2pix-trunk --print-data-spec" in message and "\n" not in message


def test_wrong_rig_is_refused(datasets, tmp_path):
    copy = tmp_path / "tsn"
    shutil.copytree(datasets["pix2pix-trunk"], copy)
    manifest = json.loads((copy / "manifest.json").read_text())
    manifest["job"]["render"]["rig"] = "tsn4"
    (copy / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(TrainingDataError, match="rig 'tsn4'.*two-view"):
        open_data("pix2pix-trunk", [str(copy)])


def test_empty_missing_and_non_dataset_folders_get_one_line_errors(tmp_path):
    (tmp_path / "empty").mkdir()
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "notes.txt").write_text("hello")
    cases = {"empty": "is empty", "absent": "does not exist", "other": "no manifest.json"}
    for folder, expected in cases.items():
        with pytest.raises(TrainingDataError, match=expected) as caught:
            open_data("sketchnet", [str(tmp_path / folder)])
        assert "\n" not in str(caught.value) and "--print-data-spec" in str(caught.value)
    with pytest.raises(TrainingDataError, match="unknown"):
        open_data("gan", [str(tmp_path)])


# ------------------------------------------------------------------------------------------ split
def test_split_puts_every_tree_in_exactly_one_part_with_the_fractions():
    keys = [(f"digest{j}", f"job-{i:08d}") for j in range(2) for i in range(2000)]
    split = Split.by_hash(keys)
    sets = [set(split.parts[part]) for part in PARTS]
    assert sum(map(len, sets)) == len(keys) and set().union(*sets) == set(keys)
    assert all(not (a & b) for i, a in enumerate(sets) for b in sets[i + 1:])
    shares = np.array([len(s) for s in sets]) / len(keys)
    np.testing.assert_allclose(shares, [0.8, 0.1, 0.1], atol=0.02)
    # Same tree id under another job's digest: an independent draw, so the parts differ for some ids.
    assert any(split_part(("digest0", k[1])) != split_part(("digest1", k[1])) for k in keys[:200])
    # Stable: the same keys in another order, or among more keys, land in the same parts.
    again = Split.by_hash(list(reversed(keys)) + [("digest9", "x")])
    assert all(split.part_of(k) == again.part_of(k) for k in keys)


def test_split_of_real_folders_is_stable_when_a_second_folder_is_added(datasets):
    one = open_data("sketchnet", [str(datasets["sketchnet"])])
    two = open_data("sketchnet", [str(datasets["sketchnet"]), str(datasets["sketchnet-b"])])
    assert len(set(two.keys)) == len(one.keys) + 2  # the same tree ids of two jobs never collide
    first, second = one.split(), two.split()
    assert all(first.part_of(k) == second.part_of(k) for k in one.keys)
    # Views of one tree never straddle parts.
    for part in PARTS:
        dataset = TaskDataset(two, second, part)
        trees = {(dataset.data.sources[s].spec_digest, str(dataset.data.sources[s].view_trees[r]))
                 for s, r in dataset.rows}
        assert trees <= set(second.parts[part])


def test_the_same_job_given_twice_is_refused(datasets):
    with pytest.raises(TrainingDataError, match="same tree"):
        open_data("sketchnet", [str(datasets["sketchnet"]), str(datasets["sketchnet"])])


def test_split_json_round_trip_and_frozen_reapply(tmp_path):
    old = [("d1", f"t{i}") for i in range(300)]
    frozen = Split.by_hash(old)
    frozen.save(tmp_path / "split.json")
    loaded = Split.load(tmp_path / "split.json")
    assert loaded == frozen
    new = [("d2", f"t{i}") for i in range(50)]
    grown = loaded.reapply(old[10:] + new)  # ten old trees gone, fifty new
    for part in ("val", "test"):
        assert set(grown.parts[part]) == set(frozen.parts[part]) - set(old[:10])
    assert set(new) <= set(grown.parts["train"])
    (tmp_path / "bad.json").write_text(json.dumps({"format": "treefarm-split", "version": 1,
                                                   "fractions": [0.8, 0.1, 0.1], "train": [["a", "b"]],
                                                   "val": [["a", "b"]], "test": []}))
    with pytest.raises(TrainingDataError, match="more than one part"):
        Split.load(tmp_path / "bad.json")
    with pytest.raises(TrainingDataError, match="fractions"):
        Split.by_hash(old, (0.5, 0.5, 0.5))


# ------------------------------------------------------------------------------------------ rejections
def test_rejected_trees_are_left_out_and_counted(datasets, tmp_path):
    copy = tmp_path / "reviewed"
    shutil.copytree(datasets["sketchnet"], copy)
    ids = sorted(open_data("sketchnet", [str(copy)]).sources[0].trees)
    store = ReviewStore(copy / "reviews.sqlite")
    store.put_verdict(ids[0], "ann", "reject", time_ms=1)
    store.put_verdict(ids[0], "bob", "approve", time_ms=2)  # one reviewer's reject suffices
    store.put_verdict(ids[1], "ann", "reject", time_ms=1)
    store.put_verdict(ids[1], "ann", "approve", time_ms=5)  # changed her mind: kept
    # A verdict only in the exported Parquet (reviews kept elsewhere with --db).
    elsewhere = ReviewStore(tmp_path / "elsewhere.sqlite")
    elsewhere.put_verdict(ids[2], "cid", "reject", time_ms=3)
    export_reviews(str(copy), elsewhere)
    assert rejected_trees(str(copy)) == {ids[0], ids[2]}
    data = open_data("sketchnet", [str(copy)])
    assert data.rejected == 2 and set(data.sources[0].trees) == {ids[1]}
    split = data.split((1.0, 0.0, 0.0))
    summary = data.summary(split)
    assert summary["rejected"] == 2 and summary["trees"]["train"] == 1 and summary["views"]["train"] == 4
    assert {TaskDataset(data, split, "train").record(i)["tree_id"] for i in range(4)} == {ids[1]}


# ------------------------------------------------------------------------------------------ records
def test_plain_record_is_the_preprocessed_view(datasets):
    from farm.dataset.torch_dataset import ViewsDataset

    data = open_data("sketchnet", [str(datasets["sketchnet"])])
    dataset = TaskDataset(data, Split.by_hash(data.keys, (1.0, 0.0, 0.0)), "train")
    record = dataset.record(0)
    raw = ViewsDataset(str(datasets["sketchnet"]), outputs=["sketch_tsn"])[int(dataset.rows[0][1])]
    assert raw["tree_id"] == record["tree_id"]
    np.testing.assert_array_equal(record["input"], preprocess(raw["sketch_tsn"].numpy()[0], "sketch", 224))


@pytest.mark.parametrize("name", ["sketchnet", "pix2pix-silhouette"])
def test_augmentation_is_deterministic_per_seed_epoch_and_index(datasets, name):
    data = open_data(name, [str(datasets[name])])
    split = Split.by_hash(data.keys, (1.0, 0.0, 0.0))
    a = TaskDataset(data, split, "train", augment=True, seed=7)
    b = TaskDataset(data, split, "train", augment=True, seed=7)
    for index in range(2):
        np.testing.assert_array_equal(a.record(index, epoch=1)["input"], b.record(index, epoch=1)["input"])
    assert not np.array_equal(a.record(0, epoch=1)["input"], a.record(0, epoch=2)["input"])
    other_seed = TaskDataset(data, split, "train", augment=True, seed=8)
    assert not np.array_equal(a.record(0, epoch=1)["input"], other_seed.record(0, epoch=1)["input"])
    if name == "sketchnet":  # the hand style is swapped in about half the time
        styles = [a.record(i % len(a), epoch=e)["style"] for i in range(4) for e in range(8)]
        assert 0.2 < styles.count("sketch_hand") / len(styles) < 0.8
    else:  # the target and mask move with the input
        plain = TaskDataset(data, split, "train").record(0)
        on_mask = plain["mask"][0][plain["input"][0] > 0.5].mean()  # share of edge ink on the foreground
        for epoch in range(3):
            record = a.record(0, epoch=epoch)
            assert not np.array_equal(record["mask"], plain["mask"])
            assert record["mask"][0][record["input"][0] > 0.5].mean() > 0.9 * on_mask


def test_ray_dataset_gives_the_same_records(datasets, ray_session):
    data = open_data("pix2pix-trunk", [str(datasets["pix2pix-trunk"])])
    dataset = TaskDataset(data, Split.by_hash(data.keys, (1.0, 0.0, 0.0)), "train", augment=True, seed=3)
    rows = to_ray_dataset(dataset, epoch=4, batch_size=2).take_all()
    assert len(rows) == len(dataset)
    expected = {(r["tree_id"], r["view"]): r for r in (dataset.record(i, epoch=4) for i in range(len(dataset)))}
    for row in rows:
        want = expected[(str(row["tree_id"]), int(row["view"]))]
        np.testing.assert_array_equal(row["input"], want["input"])
        np.testing.assert_array_equal(row["target"], want["target"])
    batches = list(to_ray_dataset(dataset, epoch=4, columns=["input", "target", "mask"]).iter_torch_batches(
        batch_size=2))
    assert sum(len(b["input"]) for b in batches) == len(dataset)
    assert batches[0]["input"].dtype == torch.float32 and batches[0]["input"].shape[1:] == (3, 256, 256)
