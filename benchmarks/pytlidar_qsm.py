"""PyTLidar (a Python port of TreeQSM) beside our cloud skeleton in bench_reconstruct_cloud.py: its cylinders for
one cloud, read as a Skeleton so the same metrics score both.

In: (N, 3) points, metres, Z up. Out: a `PyTLidarRun` (Skeleton, seconds, cylinder count, patch inputs). PyTLidar
is GPL and installed for the benchmark only (pip install PyTLidar); it runs in a child process (this file run as
a script: POINTS.npy in, cylinders .npz out) so that a time limit can stop it and its numba and matplotlib state
stay out of the bench. By hand: .venv/bin/python benchmarks/pytlidar_qsm.py POINTS.npy OUT.npz [--patch PD1 PD2MIN
PD2MAX]
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")  # tree_data draws its distribution figures whatever the plot option
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
from scipy.sparse import coo_matrix  # noqa: E402
from scipy.sparse.csgraph import breadth_first_order  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from species.skeleton import Skeleton  # noqa: E402

CYLINDER_FIELDS = ("start", "axis", "length", "radius", "parent", "extension", "branch", "BranchOrder")
PATCH_KEYS = ("PatchDiam1", "PatchDiam2Min", "PatchDiam2Max", "BallRad1", "BallRad2")
PYTLIDAR_MISSING = "PyTLidar not installed: pip install PyTLidar"


class PyTLidarFailed(Exception):
    """PyTLidar gave no model for a cloud: its own error, the time limit, or cylinders that make no tree."""


@dataclass(frozen=True, eq=False)
class PyTLidarRun:
    """One PyTLidar model: its cylinders as a Skeleton (the points' frame), the QSM's seconds (one core, numba's
    compiled code cached), how many cylinders it fitted and its patch inputs (metres, by TreeQSM name)."""

    skeleton: Skeleton
    seconds: float
    n_cylinders: int
    inputs: dict


def cylinders_to_skeleton(start, axis, length, radius, parent, extension, order) -> Skeleton:
    """A Skeleton from C TreeQSM cylinders (start (C, 3) and unit axis (C, 3) metres, length and radius (C,) metres,
    parent and extension (C,) cylinder indices, -1 and 0 for none, order (C,) branch order).

    Each cylinder gives two nodes, its start and its end, both with its radius. A cylinder that continues its
    parent starts from the parent's end. The first cylinder of a branch starts from a junction node put on its
    parent's axis, at the foot of the perpendicular from its start, splitting the parent there (so no edge runs
    back along the parent). A cylinder TreeQSM left without a parent (a branch whose parent fit failed) starts
    from the nearest node of the tree grown from cylinder 0, the trunk's base. Nodes are then numbered
    breadth-first from that base, parents first.
    """
    start, axis = np.asarray(start, np.float64), np.asarray(axis, np.float64)
    length, radius = np.asarray(length, np.float64), np.asarray(radius, np.float64)
    parent, extension = np.asarray(parent, np.int64), np.asarray(extension, np.int64)
    order = np.asarray(order, np.int64)
    n = len(radius)
    if n == 0 or parent[0] >= 0:
        raise PyTLidarFailed(f"{n} cylinders and no base cylinder (cylinder 0 has parent {parent[:1].tolist()})")
    end = start + axis * length[:, None]
    # Nodes: starts 0..n-1, ends n..2n-1, then one junction per branch start, in order along each parent.
    node_parent = np.concatenate([np.full(n, -1), np.arange(n)])
    child = np.flatnonzero(parent >= 0)
    continues = extension[parent[child]] == child
    node_parent[child[continues]] = parent[child[continues]] + n
    branching = child[~continues]
    host = parent[branching]
    along = np.clip(np.einsum("ij,ij->i", start[branching] - start[host], axis[host]), 0.0, length[host])
    sort = np.lexsort((along, host))
    branching, host, along = branching[sort], host[sort], along[sort]
    junction = 2 * n + np.arange(len(branching))
    first_on_host = np.r_[True, host[1:] != host[:-1]]
    junction_parent = np.where(first_on_host, host, np.r_[-1, junction[:-1]])
    last_on_host = np.r_[host[1:] != host[:-1], True]
    node_parent[n + host[last_on_host]] = junction[last_on_host]  # the host's end hangs from its last junction
    node_parent[branching] = junction
    node_parent = np.concatenate([node_parent, junction_parent])
    positions = np.concatenate([start, end, start[host] + along[:, None] * axis[host]])
    node_radius = np.concatenate([radius, radius, radius[host]])
    node_order = np.concatenate([order, order, order[host]])
    # Cylinders of the base's tree: follow parents to their roots by pointer doubling.
    root = np.where(parent >= 0, parent, np.arange(n))
    while np.any(root[root] != root):
        root = root[root]
    orphans = np.flatnonzero((parent < 0) & (np.arange(n) > 0))
    if len(orphans):
        main = np.flatnonzero(root == 0)
        _, nearest = cKDTree(np.concatenate([start[main], end[main]])).query(start[orphans])
        node_parent[orphans] = np.concatenate([main, main + n])[nearest]
    total = len(positions)
    children = np.flatnonzero(node_parent >= 0)
    graph = coo_matrix((np.ones(len(children)), (node_parent[children], children)), shape=(total, total)).tocsr()
    walk = breadth_first_order(graph, 0, directed=True, return_predecessors=False)
    new_index = np.empty(total, np.int64)
    new_index[walk] = np.arange(total)
    walked_parent = node_parent[walk]
    return Skeleton(positions[walk], np.where(walked_parent < 0, -1, new_index[walked_parent]),
                            node_radius[walk], np.minimum(node_order[walk], 255))


def _first_error(stderr: str) -> str:
    """The root exception line of a child's traceback (PyTLidar prints the cause before its own RuntimeError)."""
    errors = re.findall(r"^(\w+(?:Error|Exception)\b.*)$", stderr, flags=re.MULTILINE)
    lines = [line for line in stderr.splitlines() if line.strip() and "findfont" not in line]
    return errors[0] if errors else (lines[-1] if lines else "no message")


def pytlidar_run(points: np.ndarray, timeout_s: float) -> PyTLidarRun:
    """PyTLidar's TreeQSM on (N, 3) points (metres, Z up) in a child process given `timeout_s` seconds;
    PyTLidarFailed when it fails."""
    with tempfile.TemporaryDirectory() as work:
        source, target = Path(work) / "points.npy", Path(work) / "cylinders.npz"
        np.save(source, np.asarray(points, np.float64))
        environment = {**os.environ, "NUMBA_NUM_THREADS": "1", "MPLBACKEND": "Agg"}
        try:
            done = subprocess.run([sys.executable, str(Path(__file__).resolve()), str(source), str(target)],
                                  capture_output=True, text=True, timeout=timeout_s, env=environment)
        except subprocess.TimeoutExpired:
            raise PyTLidarFailed(f"no model within {timeout_s:.0f} s") from None
        if done.returncode != 0:
            raise PyTLidarFailed(_first_error(done.stderr))
        with np.load(target) as cylinders:
            skeleton = cylinders_to_skeleton(cylinders["start"], cylinders["axis"], cylinders["length"],
                                             cylinders["radius"], cylinders["parent"], cylinders["extension"],
                                             cylinders["BranchOrder"])
            inputs = {key: float(cylinders[key][0]) for key in PATCH_KEYS}
            return PyTLidarRun(skeleton, float(cylinders["seconds"]), len(cylinders["radius"]), inputs)


def pytlidar_missing(timeout_s: float) -> str | None:
    """Why PyTLidar's rows stay empty (not installed here, or turned off by a time limit of 0), else None."""
    if importlib.util.find_spec("PyTLidar") is None:
        return PYTLIDAR_MISSING
    return "PyTLidar off (--pytlidar-timeout 0)" if timeout_s <= 0 else None


# ------------------------------------------------------------------------------- the child process's side
def qsm_inputs(points: np.ndarray, patch: tuple[float, float, float] | None = None) -> dict:
    """PyTLidar's inputs for `points`: its own estimate (TreeQSM's define_input: patch sizes from the stem radius
    fitted near the base, ball radii from the point spacing there) unless `patch` gives PatchDiam1, PatchDiam2Min
    and PatchDiam2Max in metres, whose ball radii are then TreeQSM's create_input defaults (+2 cm and +1 cm)."""
    from PyTLidar import build_inputs

    inputs = build_inputs(points, n_patchdiam=(1, 1, 1), savemat=0, savetxt=0, plot=0, disp=0, savepdf=0)[0]
    if patch is not None:
        first, least, most = (float(v) for v in patch)
        inputs.update(PatchDiam1=[first], PatchDiam2Min=[least], PatchDiam2Max=[most], BallRad1=[first + 0.02],
                      BallRad2=[most + 0.01])
    # Point-model distances and the triangulated stem are TreeQSM's own reports; the bench scores the cylinders.
    inputs.update(Dist=0, Tria=0, OnlyTree=1)
    return inputs


def run(points: np.ndarray, patch=None) -> dict[str, np.ndarray]:
    """The first (only) model's cylinder arrays, its seconds and the patch inputs, as an .npz-ready dict."""
    from PyTLidar import run_qsm

    inputs = qsm_inputs(points, patch)
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as results:  # TreeQSM writes figures and files beside itself
        models, _ = run_qsm(points, inputs, results_dir=results)
    seconds = time.perf_counter() - started
    if not models:
        raise RuntimeError("PyTLidar fitted no cylinder (every segment too small for its patch sizes)")
    cylinder = models[0]["cylinder"]
    out = {name: np.asarray(cylinder[name]) for name in CYLINDER_FIELDS}
    out.update({key: np.asarray(inputs[key], np.float64).ravel() for key in PATCH_KEYS})
    out["seconds"] = np.float64(seconds)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("points", help=".npy of (N, 3) points, metres, Z up")
    parser.add_argument("out", help=".npz to write the cylinders to")
    parser.add_argument("--patch", type=float, nargs=3, metavar=("PD1", "PD2MIN", "PD2MAX"),
                        help="patch diameters in metres instead of PyTLidar's estimate")
    args = parser.parse_args()
    points = np.load(args.points).astype(np.float64)
    np.savez(args.out, **run(points, args.patch))


if __name__ == "__main__":
    main()
