"""A point cloud to a complete tree (issue 24): read, check, skeletonise (reconstruct.skeleton), measure
(reconstruct.qsm), complete by seed 003's editing steps (reconstruct.completion), mesh, and write.

In: a cloud file (`.xyz`, `.ply`, `.las`/`.laz`, ...), an (N, 3) array or a `PointCloud`. Out: a
`CloudReconstruction` holding the measured skeleton, the completed skeleton, its `TreeMesh`, the QSM measures and
the frame the files are written in: "base" (the trunk's base at the origin) or "scan" (the scan's own axes and
coordinates: the offset and up axis `read_cloud` took off are put back by the GLB's root node matrix and in the
PLY's double-precision positions).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from species.meshing.tubes_and_cards import build_mesh
from species.skeleton import Skeleton
from species.tree_mesh import TreeMesh

from .clouds import CloudError, PointCloud, read_cloud
from .completion import complete
from .qsm import qsm_measures, write_branch_csv, write_skeleton_ply
from .skeleton import CloudSkeleton, SkeletonSettings, _adjacency, cloud_skeleton
from .wood import LEAF_ON_SHARE, leaf_on_share, wood_points

__all__ = ["CloudReconstruction", "from_cloud", "FRAMES", "check_single_tree", "stem_groups"]

FRAMES = ("base", "scan")
# Several trees: the lowest STEM_BAND_M of the cloud splits into stems more than STEM_GAP_M apart, each holding
# at least STEM_SHARE of that band's points.
STEM_BAND_M = 0.5
STEM_GAP_M = 0.5
STEM_SHARE = 0.15


@dataclass(frozen=True, eq=False)
class CloudReconstruction:
    """What `from_cloud` made.

    measured : the skeleton from the points alone (base frame: the trunk's base at the origin); its QSM measures
               are `measures`. skeleton : the completed tree (twigs, leaves, grafts) that `mesh` is built from.
    frame    : "base" or "scan"; transform : (4, 4) float64 from the base frame to the frame the files use.
    fit      : the skeletonisation's record (trunk radius, spacing, points used, stage timings).
    warnings : what a user should know (a leaf-on cloud, points the graph could not join).
    method   : "cloud", or "photos" for `from_photos`, whose SfM record is `provenance` (both go in the extras).
    """

    measured: Skeleton
    skeleton: Skeleton
    mesh: TreeMesh
    measures: dict
    frame: str
    transform: np.ndarray
    fit: CloudSkeleton
    cloud: PointCloud
    warnings: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    method: str = "cloud"
    provenance: dict = field(default_factory=dict)

    @property
    def base_points(self) -> np.ndarray:
        """(N, 3) float64: the cloud's points in the base frame, the skeleton's and the mesh's (its working frame
        less the measured root)."""
        return self.cloud.points.astype(np.float64) - self.fit.skeleton.positions[0].astype(np.float64)

    def in_scan_frame(self) -> tuple[Skeleton, TreeMesh]:
        """The completed skeleton and the mesh moved by `transform` into the scan's own coordinates (what a true
        tree the scan was sampled from is in)."""
        rotation, shift = self.transform[:3, :3], self.transform[:3, 3]

        def moved(points: np.ndarray) -> np.ndarray:
            return (points.astype(np.float64) @ rotation.T + shift).astype(np.float32)

        def moved_part(part):
            return replace(part, vertices=moved(part.vertices),
                           normals=(part.normals.astype(np.float64) @ rotation.T).astype(np.float32))

        leaves = (self.transform @ self.skeleton.leaves.astype(np.float64)).astype(np.float32)
        skeleton = replace(self.skeleton, positions=moved(self.skeleton.positions), leaves=leaves)
        mesh = replace(self.mesh, bark=moved_part(self.mesh.bark), leaves=moved_part(self.mesh.leaves))
        return skeleton, mesh

    @property
    def extras(self) -> dict:
        """The GLB's root-node extras: the frame, the scan's offset and up axis, the method and the measures."""
        return {"treefarm": {"method": self.method, **self.provenance, "frame": self.frame,
                             "source": self.cloud.source,
                             "scan_offset_m": [float(v) for v in self.cloud.offset], "scan_up": self.cloud.up,
                             "base_in_scan_m": [float(v) for v in self.transform[:3, 3]],
                             "measures": self.measures}}

    def glb(self) -> bytes:
        transform = None if self.frame == "base" else self.transform
        return self.mesh.to_glb(transform=transform, extras=self.extras)

    def write(self, out: str | Path, *, skeleton_ply: str | Path | None = None,
              qsm_csv: str | Path | None = None) -> None:
        """The GLB at `out`, and the PLY skeleton and the branch table when asked; each file is written whole to
        a temporary name first, so a failure leaves no half file."""
        jobs = [(Path(out), lambda p: p.write_bytes(self.glb()))]
        rotation = self.transform[:3, :3]
        if skeleton_ply is not None:
            if self.frame == "base":
                jobs.append((Path(skeleton_ply), lambda p: write_skeleton_ply(self.measured, p)))
            else:
                turned = _rotated(self.measured, rotation)
                jobs.append((Path(skeleton_ply), lambda p: write_skeleton_ply(turned, p, offset=self.transform[:3, 3])))
        if qsm_csv is not None:
            jobs.append((Path(qsm_csv), lambda p: write_branch_csv(self.measured, p)))
        for path, _ in jobs:
            path.parent.mkdir(parents=True, exist_ok=True)
        written = []
        try:
            for path, write in jobs:
                partial = path.with_name(path.name + ".partial")
                write(partial)
                written.append((partial, path))
        except BaseException:
            for partial, _ in written:
                partial.unlink(missing_ok=True)
            raise
        for partial, path in written:
            partial.replace(path)


def _rotated(skeleton: Skeleton, rotation: np.ndarray) -> Skeleton:
    positions = (skeleton.positions.astype(np.float64) @ rotation.T).astype(np.float32)
    return Skeleton(positions, skeleton.parent, skeleton.radius, skeleton.order, np.zeros((0, 4, 4), np.float32),
                    np.zeros(0, np.int32))


def stem_groups(points: np.ndarray, ground: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The points within STEM_BAND_M above `ground` (a mask) and their group labels, points linked within
    STEM_GAP_M sharing one: each group near the ground is a stem."""
    low = points[:, 2] - ground <= STEM_BAND_M
    if low.sum() < 2:
        return low, np.zeros(int(low.sum()), np.int64)
    pairs = cKDTree(points[low]).query_pairs(STEM_GAP_M, output_type="ndarray")
    return low, connected_components(_adjacency(pairs, int(low.sum())), directed=False)[1]


def check_single_tree(cloud: PointCloud) -> None:
    """CloudError when the cloud's lowest STEM_BAND_M holds several stems (`stem_groups`) that are each at least
    STEM_SHARE of the band."""
    mask, label = stem_groups(cloud.points)
    low = cloud.points[mask]
    if len(low) < 10:
        return
    sizes = np.bincount(label)
    stems = np.flatnonzero(sizes >= STEM_SHARE * len(low))
    if len(stems) > 1:
        centres = [low[label == s, :2].mean(axis=0).round(2).tolist() for s in stems]
        raise CloudError(f"{cloud.source} holds {len(stems)} trees (stems at x, y = {centres} m, more than "
                         f"{STEM_GAP_M} m apart near the ground): allowed one tree a cloud; split the scan first")


def from_cloud(cloud, *, up: str = "z", frame: str = "base", completion: bool = True, twigs: str | None = "alternate",
               seed: int = 0, settings: SkeletonSettings | None = None, separate_leaves: bool | None = None,
               name: str = "tree") -> CloudReconstruction:
    """A tree from a point cloud.

    cloud      : a path, an (N, 3) array or a PointCloud; up : the cloud's up axis (`clouds.UP_AXES`).
    frame      : "base" or "scan" (see the module docstring).
    completion : seed 003's editing (trunk identification, twig pruning, gap grafting, twigs and leaves by
                 phyllotaxis); off, the mesh is the measured skeleton's bark only. twigs : the phyllotaxis pattern.
    seed       : the completion's random draws (numpy Generator seeded with it): same cloud, same seed, same bytes.
    separate_leaves : drop leaf points before skeletonising (`reconstruct.wood`); None does so when the cloud
                 looks leaf-on, with a warning either way.
    Raises CloudError (one line) for a cloud that cannot be one tree.
    """
    if frame not in FRAMES:
        raise CloudError(f"frame {frame!r} is not known: allowed {', '.join(FRAMES)}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise CloudError(f"seed {seed!r} is invalid: allowed an integer >= 0")
    timings: dict[str, float] = {}
    clock = time.perf_counter()
    if not isinstance(cloud, PointCloud):
        cloud = read_cloud(cloud, up=up)
    check_single_tree(cloud)
    warnings: list[str] = []
    points = cloud.points
    share = leaf_on_share(points)
    looks_leafy = share >= LEAF_ON_SHARE
    if separate_leaves or (separate_leaves is None and looks_leafy):
        keep = wood_points(points)
        warnings.append(f"{cloud.source} looks leaf-on ({share:.0%} of its crown points are not linear): "
                        f"{(~keep).sum()} leaf points were set aside; the branches will be coarse")
        points = points[keep]
    elif looks_leafy:
        warnings.append(f"{cloud.source} looks leaf-on ({share:.0%} of its crown points are not linear) and "
                        f"leaves were kept: the skeleton will be coarse")
    timings["read"] = time.perf_counter() - clock
    working = cloud if len(points) == len(cloud.points) else PointCloud(
        points, cloud.offset, cloud.up, cloud.up_rotation, None, cloud.source)
    fit = cloud_skeleton(working, settings)
    if fit.n_reached < fit.n_used:
        warnings.append(f"{fit.n_used - fit.n_reached} of {fit.n_used} points could not be joined to the tree")
    clock = time.perf_counter()
    root = fit.skeleton.positions[0].astype(np.float64)
    measured = Skeleton((fit.skeleton.positions - fit.skeleton.positions[0]), fit.skeleton.parent,
                        fit.skeleton.radius, fit.skeleton.order)
    measures = qsm_measures(measured)
    measures["trunk_radius_fit_m"] = fit.trunk_radius
    timings["measures"] = time.perf_counter() - clock
    clock = time.perf_counter()
    rng = np.random.default_rng(seed)
    tree = complete(measured, rng, twigs=twigs) if completion else measured
    timings["completion"] = time.perf_counter() - clock
    clock = time.perf_counter()
    mesh = build_mesh(tree, {"name": name})
    timings["mesh"] = time.perf_counter() - clock
    transform = np.eye(4)
    transform[:3, :3] = cloud.up_rotation.T
    transform[:3, 3] = cloud.up_rotation.T @ (root + cloud.offset)
    timings = {**{f"skeleton.{k}": v for k, v in fit.timings.items()}, **timings}
    return CloudReconstruction(measured, tree, mesh, measures, frame, transform, fit, cloud, warnings, timings)
