"""What each `farm` command imports on its cheap paths: `--help` and a bad argument import none of the heavy
libraries, and no command imports torch, Ray or pycolmap before it needs them (issue 48, point 13).

Each case runs in a fresh interpreter (`python -c`), as a user's `farm ...` does, and reads `sys.modules` after
`farm.cli.main` returns. The start-up times are measured in benchmarks/bench_startup.py, not asserted here.
"""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from farm.cli import COMMANDS, build_parser, main

REPO = Path(__file__).resolve().parents[2]
TREE1 = REPO.parent / "shared" / "data" / "pointclouds" / "tree1.xyz"
AHN = REPO.parent / "shared" / "data" / "pointclouds" / "street_trees_ahn" / "ahn" / "filtered_tree_121922_487459.las"

# Imported only by the commands that run them, and only once their arguments are checked.
RUNTIMES = ("torch", "ray", "pycolmap", "onnxruntime", "mlflow", "pyrender", "OpenGL", "bpy", "matplotlib")
# The parser (every command's --help) imports none of these either.
LIBRARIES = RUNTIMES + ("scipy", "cv2", "pandas", "pyarrow", "trimesh", "laspy", "yaml", "tqdm")

_PROBE = """
import sys
from farm.cli import main
try:
    status = main(sys.argv[2:])
except SystemExit as exit:
    status = exit.code
print(" ".join(sorted(sys.modules)))
print(status)
print(" ".join(sorted(name for name in sys.argv[1].split(",") if name in sys.modules)))
"""


def _run(argv: list[str], cwd: Path) -> tuple[int, set[str], set[str]]:
    """(exit status, which of LIBRARIES are in sys.modules, every module name in it) after `farm ARGV` in a fresh
    interpreter."""
    done = subprocess.run([sys.executable, "-c", _PROBE, ",".join(LIBRARIES), *argv], capture_output=True,
                          text=True, cwd=cwd, timeout=120, env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"})
    lines = done.stdout.splitlines()
    assert len(lines) >= 3, done.stderr
    return int(lines[-2]), set(lines[-1].split()), set(lines[-3].split())


def _imported(argv: list[str], cwd: Path) -> tuple[int, set[str]]:
    """(exit status, which of LIBRARIES are in sys.modules) after `farm ARGV` in a fresh interpreter."""
    status, libraries, _ = _run(argv, cwd)
    return status, libraries


def _commands() -> list[str]:
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    return sorted(sub.choices)


def test_the_command_table_names_every_command_its_module_registers():
    # `farm COMMAND` imports only COMMANDS[COMMAND]: a command registered by another module would not be found
    assert _commands() == sorted(COMMANDS)
    for command, module in COMMANDS.items():
        sub = next(a for a in build_parser(command)._actions if a.dest == "command")
        assert command in sub.choices, (command, module)


def test_every_commands_help_imports_no_heavy_library(tmp_path):
    for command in _commands():
        status, imported = _imported([command, "--help"], tmp_path)
        assert status == 0 and not imported, (command, imported)


def test_version_imports_no_heavy_library_and_says_the_version(tmp_path, capsys):
    status, imported = _imported(["--version"], tmp_path)
    assert status == 0 and not imported, imported
    with pytest.raises(SystemExit) as exit:
        main(["--version"])
    assert exit.value.code == 0
    assert re.fullmatch(r"farm \(treefarm\) (\d+\.\d+\S*|\(not installed\))\n", capsys.readouterr().out)


# (argv, the libraries it may import besides none of RUNTIMES): a cheap real run or a bad argument of each command
CHEAP_RUNS = [
    (["species"], {"scipy"}),  # the one real run: it lists the presets
    (["tree", "--species", "maple", "--seed", "-3", "--out", "{tmp}/m.glb"], {"cv2"}),
    (["render", "--species", "maple", "--seed", "-1", "--out", "{tmp}/views"], {"cv2"}),
    (["generate", "--trees", "0", "--out", "{tmp}/job", "--quiet"], {"scipy", "cv2", "yaml"}),
    (["status", "{tmp}/none"], {"pyarrow"}),
    (["validate", "{tmp}/none"], {"pyarrow"}),
    (["inspect", "{tmp}/none"], {"cv2", "pandas", "pyarrow"}),
    (["review", "{tmp}/none", "--port", "99999"], {"cv2"}),
    (["library", "--out", "{tmp}/library", "--quiet", "--workers", "0"], {"scipy", "cv2", "yaml"}),
    (["train", "sketchnet", "--data", "{tmp}/none", "--workers", "0"], {"pyarrow"}),
    (["evaluate", "--data", "{tmp}/none", "--out", "{tmp}/report", "--workers", "0"], {"cv2"}),
    # reconstruct checks its arguments before it imports anything heavy
    (["reconstruct", "{tmp}/none.xyz", "--out", "{tmp}/tree.glb"], set()),
    (["reconstruct", "{tmp}/none.png", "--out", "{tmp}/tree.glb"], set()),
    (["reconstruct", "{tmp}/none.png", "--out", "{tmp}/tree.txt"], set()),
    (["reconstruct", "{tmp}/photos", "--method", "photos", "--out", "{tmp}/tree.glb", "--height", "-1"], set()),
]


@pytest.mark.parametrize("argv, allowed", CHEAP_RUNS, ids=[" ".join(argv[:2]) for argv, _ in CHEAP_RUNS])
def test_a_cheap_run_imports_no_runtime_it_does_not_need(argv, allowed, tmp_path):
    (tmp_path / "photos").mkdir()
    (tmp_path / "photos" / "a.png").write_bytes(b"")
    status, imported = _imported([word.format(tmp=tmp_path) for word in argv], tmp_path)
    assert status == (0 if argv == ["species"] else 2), status  # the others are refused: one line, exit 2
    assert imported <= set(allowed), imported - set(allowed)


# What a point-cloud reconstruction may import besides our own packages: the parts of numpy and scipy the skeleton
# uses and Pillow (the GLB's PNG textures; its image plugins load as it saves), and what numpy's text reader loads
# on first use. Of ours, no trainer, renderer, dataset, job or other method's module.
CLOUD_RUN_BASE = "import numpy, scipy.sparse.csgraph, scipy.spatial, PIL.Image, PIL.PngImagePlugin"
CLOUD_RUN_EXTRA = {"gzip"}
OURS = ("farm", "species", "reconstruct", "trainers", "renderers")
CLOUD_RUN_NOT_OURS = ("farm.commands.train", "farm.commands.evaluate", "farm.commands.tree", "farm.commands.render",
                      "farm.commands.inspect", "farm.dataset", "farm.jobs", "trainers", "renderers",
                      "reconstruct.from_sketch", "reconstruct.from_photos", "reconstruct.networks",
                      "species.weber_penn", "species.colonization")

# What a point-cloud reconstruction may import of LIBRARIES: scipy (the skeleton's graph and k-d trees) and no more;
# a text cloud is read by numpy and the CSVs written without pandas.
CLOUD_RUN_LIBRARIES = {"scipy"}


@pytest.mark.skipif(not TREE1.is_file(), reason="shared/data/pointclouds/tree1.xyz is missing")
def test_a_point_cloud_reconstruction_needs_no_torch_ray_or_pycolmap(tmp_path):
    status, imported, modules = _run(["reconstruct", str(TREE1), "--out", str(tmp_path / "tree.glb"), "--qsm-csv",
                                      str(tmp_path / "q.csv"), "--branches-csv", str(tmp_path / "b.csv")], tmp_path)
    assert status == 0 and (tmp_path / "q.csv").is_file() and (tmp_path / "b.csv").is_file()
    assert not imported & set(RUNTIMES), imported & set(RUNTIMES)
    assert imported <= CLOUD_RUN_LIBRARIES, imported - CLOUD_RUN_LIBRARIES
    # the GLB's textures are encoded without Pillow (species.meshing.png writes truecolour PNGs itself)
    assert "PIL" not in modules


@pytest.mark.skipif(not AHN.is_file(), reason="shared/data/pointclouds/street_trees_ahn is missing")
def test_an_uncompressed_las_scan_is_read_without_laspy(tmp_path):
    # laspy imports an HTTP client (for COPC files): a plain LAS file is read by numpy, a LAZ file still by laspy
    status, imported = _imported(["reconstruct", str(AHN), "--out", str(tmp_path / "tree.glb")], tmp_path)
    assert status == 0 and (tmp_path / "tree.glb").is_file()
    assert imported <= CLOUD_RUN_LIBRARIES, imported - CLOUD_RUN_LIBRARIES


_BLAS_PROBE = """
import os, sys
from farm.cli import main
try:
    main(sys.argv[1:])
except SystemExit:
    pass
print(os.environ.get("OPENBLAS_NUM_THREADS"))
"""


@pytest.mark.parametrize("argv, given, expected", [(["reconstruct", "none.xyz", "--out", "t.glb"], None, "1"),
                                                   (["reconstruct", "none.xyz", "--out", "t.glb"], "2", "2"),
                                                   (["species"], None, "None")])
def test_reconstruct_runs_openblas_on_one_thread_unless_the_user_chose(argv, given, expected, tmp_path):
    # OpenBLAS's idle threads spin: a reconstruction's small matrix products gain nothing from them
    env = {"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin", **({"OPENBLAS_NUM_THREADS": given} if given else {})}
    done = subprocess.run([sys.executable, "-c", _BLAS_PROBE, *argv], capture_output=True, text=True, cwd=tmp_path,
                          timeout=120, env=env)
    assert done.stdout.split()[-1] == expected, done.stderr


@pytest.mark.skipif(not TREE1.is_file(), reason="shared/data/pointclouds/tree1.xyz is missing")
def test_a_batch_of_one_cloud_runs_without_ray(tmp_path):
    # A folder --out is a batch; with one tree and no --address it runs in-process, with the batch's files.
    status, imported = _imported(["reconstruct", str(TREE1), "--out", str(tmp_path / "trees")], tmp_path)
    assert status == 0, status
    assert {p.name for p in (tmp_path / "trees").iterdir()} >= {"tree1.glb", "tree1.qsm.csv", "summary.csv",
                                                                "contact_sheet.png"}
    assert not imported & set(RUNTIMES), imported & set(RUNTIMES)


@pytest.mark.skipif(not TREE1.is_file(), reason="shared/data/pointclouds/tree1.xyz is missing")
def test_a_point_cloud_reconstructions_import_set_does_not_grow(tmp_path):
    # The command's start-up time is mostly its imports: a new library or stdlib module on this path, or another
    # command's modules, fails here (defer it to where it is used, or add it above with its reason).
    status, _, modules = _run(["reconstruct", str(TREE1), "--out", str(tmp_path / "tree.glb")], tmp_path)
    assert status == 0
    base = subprocess.run([sys.executable, "-c", CLOUD_RUN_BASE + "; import sys; print(' '.join(sys.modules))"],
                          capture_output=True, text=True, check=True, cwd=tmp_path, timeout=120,
                          env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"}).stdout.split()
    extra = {name for name in modules - set(base) if name.split(".")[0] not in OURS + ("PIL",)}
    assert extra <= CLOUD_RUN_EXTRA, extra - CLOUD_RUN_EXTRA
    assert not sorted(name for name in modules if name.startswith(CLOUD_RUN_NOT_OURS))


def test_the_program_ends_with_its_whole_output_and_status(tmp_path, capsys):
    # Run as the program (`python -m farm.cli`), main freezes the run's objects out of the exit's last collection:
    # the output is still whole and the statuses are the commands'
    env = {"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"}
    listed = subprocess.run([sys.executable, "-m", "farm.cli", "species"], capture_output=True, text=True,
                            cwd=tmp_path, timeout=120, env=env)
    assert listed.returncode == 0 and main(["species"]) == 0
    assert listed.stdout == capsys.readouterr().out
    refused = subprocess.run([sys.executable, "-m", "farm.cli", "reconstruct", "none.xyz", "--out", "t.glb"],
                             capture_output=True, text=True, cwd=tmp_path, timeout=120, env=env)
    assert refused.returncode == 2 and refused.stderr.startswith("farm: error: ") and refused.stderr.count("\n") == 1
