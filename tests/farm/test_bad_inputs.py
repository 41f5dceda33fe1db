"""Every command's bad inputs: one line on stderr naming the value, exit status 2, and nothing written.

The table runs in-process through `farm.cli.main` (fast); a few rows run end to end as `python -m farm.cli`.
"""
from __future__ import annotations

import contextlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from farm.cli import main
from farm.pipeline import run_job
from farm_standins import StandinChain, standin_spec
from renderers.contact_sheet import contact_sheet

REPO = Path(__file__).resolve().parents[2]
SAPLING = REPO.parent / "shared" / "data" / "sapling"


@pytest.fixture(scope="module")
def finished_dataset(tmp_path_factory, ray_session) -> Path:
    path = tmp_path_factory.mktemp("bad_inputs_dataset")
    run_job(standin_spec(species={"standin_a": 2, "standin_b": 1}), str(path), workers=1,
            builder_factory=StandinChain, progress=False)
    return path


WORKERS_0 = "--workers 0 is invalid: allowed an integer >= 1"
BAD_INPUTS = [
    # (argv, words of the one line); {tmp} is a folder of inputs, {good} a valid dictionary, {data} a dataset copy,
    # {damaged} the copy with a truncated trees part file
    (["tree", "--params", "{good}", "{tmp}/in/bad.json", "--out", "{tmp}/out"], "bad.json"),
    (["tree", "--params", "{good}", "{tmp}/in/other/{good_name}", "--out", "{tmp}/out"], "would both write"),
    (["tree", "--params", "{good}", "--out", "{tmp}/t.glb"], "--out"),
    (["tree", "--species", "maple", "--seed", "-3", "--out", "{tmp}/m.glb"], "--seed -3"),
    (["tree", "--species", "maple", "--format", "glb", "--out", "{tmp}/x.obj"], "--format glb"),
    (["tree", "--species", "maple", "--out", "{tmp}/dir/"], "is a folder"),
    # a dictionary that describes no tree, rather than the default tree grown silently
    (["tree", "--params", "{tmp}/in/empty.json", "--out", "{tmp}/out"], "at least one weber_penn parameter"),
    (["tree", "--params", "{tmp}/in/generator_only.json", "--out", "{tmp}/out"], "at least one weber_penn"),
    (["tree", "--params", "{tmp}/in/colonization_only.json", "--out", "{tmp}/out"], "at least one colonization"),
    (["tree", "--params", "{tmp}/in/unknown_only.json", "--out", "{tmp}/out"], "'lenght' = 3"),
    (["tree", "--params", "{tmp}/in/unknown_only.py", "--out", "{tmp}/out"], "unknown_only.py: parameter"),
    (["tree", "--params", "{tmp}/in/old_bad.py", "--out", "{tmp}/out"], "'levels' = 'three'"),
    (["render", "--species", "maple", "--size", "100000", "--out", "{tmp}/views"], "--size 100000"),
    (["render", "--species", "maple", "--seed", "-1", "--out", "{tmp}/views"], "--seed -1"),
    (["inspect", "{data}", "--rows", "-3"], "--rows -3"),
    (["inspect", "{damaged}"], "part-"),
    (["review", "{damaged}", "--port", "0", "--db", "{tmp}/reviews.sqlite"], "part-"),
    (["validate", "{tmp}"], "no manifest.json"),
    (["library", "validate", "{tmp}"], "not an asset library"),  # exit 2 as `farm validate`, not 1 (damage)
    (["library", "validate", "{data}"], "not an asset library"),
    (["export", "{data}", "--format", "stl", "--out", "{tmp}/meshes"], "--format 'stl'"),
    (["export", "{data}", "--out", "{tmp}/meshes", "--to", "{tmp}/other"], "--to"),
    (["export", "{data}"], "--out FOLDER is required"),
    (["review", "{data}", "--port", "99999"], "--port 99999"),
    (["review", "export", "{data}", "--db", "{tmp}/in"], "--db"),
    (["generate", "--trees", "0", "--out", "{tmp}/job", "--quiet"], "trees"),
    # every command on Ray refuses --workers below 1 before it starts Ray or writes anything
    (["generate", "--out", "{tmp}/job", "--quiet", "--workers", "0"], WORKERS_0),
    (["library", "--out", "{tmp}/library", "--quiet", "--workers", "0"], WORKERS_0),
    (["evaluate", "--data", "{data}", "--out", "{tmp}/report", "--workers", "0"], WORKERS_0),
    (["train", "sketchnet", "--data", "{data}", "--workers", "0"], WORKERS_0),
    (["retrain", "sketchnet", "--data", "{data}", "--workers", "0"], WORKERS_0),
    (["reconstruct", "{tmp}/in", "--out", "{tmp}/trees", "--workers", "0"], WORKERS_0),
    (["render", "--species", "maple", "--out", "{tmp}/in/bad.json"], "--out"),
    # {readonly} is a folder no one may write in
    (["generate", "--out", "{readonly}", "--trees", "2", "--quiet"], "cannot write {readonly}/_job.json: "),
    (["library", "--out", "{readonly}", "--quiet"], "cannot write {readonly}/library.json: "),
    # listing models only reads: a folder that holds no registry is not made one
    (["models", "list", "--models", "{tmp}/in"], "holds no model registry"),
    (["models", "show", "sketchnet", "--models", "{tmp}/registry"], "holds no model registry"),
    # photos SfM cannot use are refused at the first stage that can tell: reading, features, matching
    (["reconstruct", "{tmp}/photos/broken", "--height", "3", "--out", "{tmp}/tree.glb"], "cannot be read as an image"),
    (["reconstruct", "{tmp}/photos/blank", "--height", "3", "--out", "{tmp}/tree.glb"], "0 of 4 photos have 15 features"),
    (["reconstruct", "{tmp}/photos/noise", "--height", "3", "--out", "{tmp}/tree.glb"], "matching linked 0 of 4 photos"),
]
# What a line must not show of another library's wording: pyarrow's detail and our temporary file names.
FOREIGN_WORDING = ("Detail: [errno", ".tmp-")


def _truncate_a_part(data: Path) -> Path:
    part = sorted((data / "trees").glob("part-*.parquet"))[0]
    part.write_bytes(part.read_bytes()[:200])
    return part


def _files(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


def _photo_folders(folder: Path) -> None:
    """Four photos each that SfM cannot use: blank (no features), noise (features that match nothing), and one
    file that is not an image beside three blank ones (broken)."""
    for name in ("broken", "blank", "noise"):
        (folder / name).mkdir(parents=True)
    for k in range(4):
        Image.fromarray(np.full((64, 64, 3), 128, np.uint8)).save(folder / "blank" / f"grey_{k}.png")
        noise = np.random.default_rng(k).integers(0, 256, (200, 200, 3), dtype=np.uint8)
        Image.fromarray(noise).save(folder / "noise" / f"noise_{k}.png")
        (folder / "broken" / f"photo_{k}.png").write_bytes(b"not a picture" if k == 2 else
                                                           (folder / "blank" / f"grey_{k}.png").read_bytes())


def _prepare(tmp: Path, data: Path, argv: list[str]) -> list[str]:
    inputs = tmp / "in"
    (inputs / "other").mkdir(parents=True)
    good = next(iter(sorted(SAPLING.glob("*.json"))))
    (inputs / "bad.json").write_text(json.dumps({**json.loads(good.read_text()), "levels": 9}))
    shutil.copy(good, inputs / "other" / good.name)
    for name, params in (("empty.json", {}), ("generator_only.json", {"generator": "weber_penn"}),
                         ("colonization_only.json", {"generator": "colonization"}),
                         ("unknown_only.json", {"lenght": 3})):
        (inputs / name).write_text(json.dumps(params))
    (inputs / "unknown_only.py").write_text(repr({"lenght": 3, "windSpeed": 2.0}))
    (inputs / "old_bad.py").write_text(repr({"startCurv": 0.0, "levels": "three"}))
    if any("{tmp}/photos" in word for word in argv):
        _photo_folders(tmp / "photos")
    if "{damaged}" in argv:
        _truncate_a_part(data)
    return [w.format(tmp=tmp, good=good, good_name=good.name, data=data, damaged=data, readonly=tmp / "readonly")
            for w in argv]


@contextlib.contextmanager
def read_only(folder: Path):
    """`folder`, made, that no one may write in while the block runs: its mode 0o555, and where that does not stop
    writes (the tests run as root) marked immutable with `chattr +i`; skipped where neither can."""
    folder.mkdir()
    folder.chmod(0o555)
    immutable = False
    try:
        if os.access(folder, os.W_OK):
            marked = subprocess.run(["chattr", "+i", str(folder)], capture_output=True) if shutil.which("chattr") \
                else None
            if marked is None or marked.returncode != 0:
                pytest.skip("running as root, where a read-only mode does not stop writes, and chattr +i is "
                            "not allowed here")
            immutable = True
        yield folder
    finally:
        if immutable:
            subprocess.run(["chattr", "-i", str(folder)], check=True)
        folder.chmod(0o755)


@pytest.mark.parametrize("argv, named", BAD_INPUTS, ids=[" ".join(a[:1] + a[-2:]) for a, _ in BAD_INPUTS])
def test_a_bad_input_is_one_line_status_2_and_writes_nothing(tmp_path, finished_dataset, capsys, argv, named):
    data = tmp_path / "data"
    shutil.copytree(finished_dataset, data)
    readonly = tmp_path / "work" / "readonly"
    named = named.format(readonly=readonly)
    argv = _prepare(tmp_path / "work", data, argv)
    with read_only(readonly) if any(str(readonly) in word for word in argv) else contextlib.nullcontext():
        before_work, before_data = _files(tmp_path / "work"), _files(data)
        status = main(argv)
        lines = capsys.readouterr().err.strip().splitlines()
        assert status == 2 and len(lines) == 1, lines
        assert lines[0].startswith("farm: error: ") and named in lines[0], lines
        assert not any(words in lines[0] for words in FOREIGN_WORDING), lines
        assert _files(tmp_path / "work") == before_work and _files(data) == before_data


END_TO_END = [row for row in BAD_INPUTS if row[1] in ("bad.json", "--size 100000", "part-")][:3]


@pytest.mark.parametrize("argv, named", END_TO_END, ids=[a[0] for a, _ in END_TO_END])
def test_a_bad_input_end_to_end_is_one_line_and_status_2(tmp_path, finished_dataset, argv, named):
    data = tmp_path / "data"
    shutil.copytree(finished_dataset, data)
    argv = _prepare(tmp_path / "work", data, argv)
    before = _files(tmp_path)
    result = subprocess.run([sys.executable, "-m", "farm.cli", *argv], cwd=REPO, capture_output=True, text=True)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and named in lines[0], result.stderr
    assert _files(tmp_path) == before


def test_a_bad_host_is_not_blamed_on_the_port(tmp_path, finished_dataset, capsys):
    data = tmp_path / "data"
    shutil.copytree(finished_dataset, data)
    assert main(["review", str(data), "--host", "no-such-host.invalid", "--port", "0",
                 "--db", str(tmp_path / "r.sqlite")]) == 2
    line = capsys.readouterr().err.strip()
    assert "--host" in line and "choose another --port" not in line


def test_a_port_in_use_is_refused_before_the_reviews_database_is_made(tmp_path, finished_dataset, capsys):
    import socket

    data = tmp_path / "data"
    shutil.copytree(finished_dataset, data)
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        assert main(["review", str(data), "--port", str(port)]) == 2
    line = capsys.readouterr().err.strip()
    assert f"127.0.0.1:{port}" in line and "choose another --port" in line
    assert not (data / "reviews.sqlite").exists()


def test_contact_sheet_labels_are_whole():
    image = np.zeros((8, 8), np.uint8)
    a, b = (contact_sheet([("0 sc_self_pruning_forest_tree", [(name, image)])], cell=64)
            for name in ("sketch_tsn_contour_a", "sketch_tsn_contour_b"))
    assert not np.array_equal(a, b)  # the last letter of a long output name is drawn, not cut off


def test_the_torch_dataset_names_a_damaged_part_file(tmp_path, finished_dataset):
    from farm.dataset import DatasetError
    from farm.dataset.torch_dataset import ViewsDataset

    data = tmp_path / "data"
    shutil.copytree(finished_dataset, data)
    part = sorted((data / "views").glob("part-*.parquet"))[0]
    part.write_bytes(part.read_bytes()[:200])
    with pytest.raises(DatasetError, match=str(part)):
        ViewsDataset(str(data))
