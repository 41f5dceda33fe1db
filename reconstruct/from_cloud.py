"""A point cloud to a complete tree (issue 24): read, check, skeletonise (reconstruct.skeleton), measure
(reconstruct.qsm), complete by seed 003's editing steps (reconstruct.completion), mesh, and write.

In: a cloud file (`.xyz`, `.ply`, `.las`/`.laz`, ...), an (N, 3) array or a `PointCloud`. Out: a `Reconstruction`
(method "cloud") of the completed skeleton and its `TreeMesh`, whose `ScanRecord` holds the cloud, the measured
skeleton, the QSM measures and the frame the files are written in: "base" (the trunk's base at the origin) or
"scan" (the scan's own axes and coordinates: the offset and up axis `read_cloud` took off are put back by the GLB's
root node matrix and in the PLY's double-precision positions).
"""
from __future__ import annotations

import numpy as np
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from species.meshing.tubes_and_cards import build_mesh
from species.skeleton import Skeleton
from species.timing import StageTimer

from .clouds import CloudError, PointCloud, read_cloud
from .completion import ScanReach, complete
from .qsm import qsm_measures
from .result import Reconstruction, ScanRecord
from .skeleton import SkeletonSettings, _adjacency, cloud_neighbours, cloud_skeleton
from .wood import LEAF_ON_SHARE, leaf_on_share, wood_points

__all__ = ["from_cloud", "FRAMES", "check_single_tree", "stem_groups", "linked_groups"]

FRAMES = ("base", "scan")
# Several trees: the lowest STEM_BAND_M of the cloud splits into stems more than STEM_GAP_M apart, each holding
# at least STEM_SHARE of that band's points.
STEM_BAND_M = 0.5
STEM_GAP_M = 0.5
STEM_SHARE = 0.15
_CELL_DIAGONALS = 1.75  # a grid cell's side is the gap over this (more than sqrt(3), so its diagonal is shorter)


def stem_groups(points: np.ndarray, ground: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The points within STEM_BAND_M above `ground` (a mask) and their group labels, points linked within
    STEM_GAP_M sharing one: each group near the ground is a stem."""
    low = points[:, 2] - ground <= STEM_BAND_M
    if low.sum() < 2:
        return low, np.zeros(int(low.sum()), np.int64)
    return low, linked_groups(points[low], STEM_GAP_M)


def linked_groups(points: np.ndarray, gap: float) -> np.ndarray:
    """(N,) int64 group labels of (N, 3) points, points within `gap` of each other sharing one; groups numbered
    in the order of their first points (as `connected_components` numbers them). The links are counted between
    grid cells too small to hold two points farther apart than `gap`, whose points are therefore one group: a
    dense band's hundreds of thousands of links become a few between cells."""
    if not len(points):
        return np.zeros(0, np.int64)
    pairs = cKDTree(points).query_pairs(gap, output_type="ndarray")
    cell = np.floor((points - points.min(axis=0)) / (gap / _CELL_DIAGONALS)).astype(np.int64)
    _, cell_of = np.unique(cell, axis=0, return_inverse=True)
    cell_of = cell_of.ravel()
    cells = int(cell_of.max()) + 1
    keys = np.unique(cell_of[pairs[:, 0]] * cells + cell_of[pairs[:, 1]])
    _, cell_group = connected_components(_adjacency(np.column_stack([keys // cells, keys % cells]), cells),
                                         directed=False)
    group = cell_group[cell_of]
    _, first = np.unique(group, return_index=True)
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first)] = np.arange(len(first))
    return rank[group]


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
               name: str = "tree") -> Reconstruction:
    """A tree from a point cloud: its `Reconstruction` (method "cloud"; timings: "skeleton.STAGE" per stage of
    `cloud_skeleton`, then "read", "measures", "completion", "mesh"; no maps; `scan` set).

    cloud      : a path, an (N, 3) array or a PointCloud; up : the cloud's up axis (`clouds.UP_AXES`).
    frame      : "base" or "scan" (see the module docstring).
    completion : seed 003's editing (trunk identification, gap grafting, twigs and leaves by phyllotaxis), inside
                 the scan's reach (`completion.ScanReach`: nothing below the scan's lowest point, nothing beyond
                 1 m outside its convex hull) and never removing a measured node; off, the mesh is the measured
                 skeleton's bark only. twigs : the phyllotaxis pattern.
    seed       : the completion's random draws (numpy Generator seeded with it): same cloud, same seed, same bytes.
    separate_leaves : drop leaf points before skeletonising (`reconstruct.wood`); None (and False) keep them, with
                 a warning when the cloud looks leaf-on: the bark then follows the leaves' points too, as AdTree's
                 does, which fits a leafy scan far closer than branches from its wood points alone.
    Raises CloudError (one line) for a cloud that cannot be one tree.
    """
    if frame not in FRAMES:
        raise CloudError(f"frame {frame!r} is not known: allowed {', '.join(FRAMES)}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise CloudError(f"seed {seed!r} is invalid: allowed an integer >= 0")
    timer = StageTimer()
    if not isinstance(cloud, PointCloud):
        cloud = read_cloud(cloud, up=up)
    check_single_tree(cloud)
    warnings: list[str] = []
    points = cloud.points
    neighbours = cloud_neighbours(cloud)  # the leaf test's and the skeleton's outlier filter's, queried once
    share = leaf_on_share(points, neighbours=neighbours)
    looks_leafy = share >= LEAF_ON_SHARE
    if separate_leaves:
        keep = wood_points(points)
        warnings.append(f"{cloud.source}: {(~keep).sum()} leaf points were set aside ({share:.0%} of its crown "
                        f"points are not linear); the branches will be coarse")
        points = points[keep]
    elif looks_leafy:
        warnings.append(f"{cloud.source} looks leaf-on ({share:.0%} of its crown points are not linear) and "
                        f"leaves were kept: the bark follows the leaves' points too")
    timer.lap("read")
    working = cloud if len(points) == len(cloud.points) else PointCloud(
        points, cloud.offset, cloud.up, cloud.up_rotation, None, cloud.source)
    fit = cloud_skeleton(working, settings, neighbours=neighbours if working is cloud else None)  # its own stages
    if fit.n_reached < fit.n_used:
        warnings.append(f"{fit.n_used - fit.n_reached} of {fit.n_used} points could not be joined to the tree")
    with timer.stage("measures"):
        root = fit.skeleton.positions[0].astype(np.float64)
        measured = Skeleton((fit.skeleton.positions - fit.skeleton.positions[0]), fit.skeleton.parent,
                            fit.skeleton.radius, fit.skeleton.order)
        measures = qsm_measures(measured, cloud.points.astype(np.float64) - root)
        measures["trunk_radius_fit_m"] = fit.trunk_radius
    with timer.stage("completion"):
        # Completion adds only inside the scan's reach, above its lowest point, and prunes no measured twig.
        reach = ScanReach(points.astype(np.float64) - root, ground=-float(root[2]))
        tree = complete(measured, np.random.default_rng(seed), twigs=twigs, prune=False, reach=reach) \
            if completion else measured
    with timer.stage("mesh"):
        mesh = build_mesh(tree, {"name": name, "mesh_ground_clear": True})
    transform = np.eye(4)
    transform[:3, :3] = cloud.up_rotation.T
    transform[:3, 3] = cloud.up_rotation.T @ (root + cloud.offset)
    timings = {**{f"skeleton.{k}": v for k, v in fit.timings.items()}, **timer.seconds}
    return Reconstruction("cloud", tree, mesh, timings=timings, warnings=tuple(warnings),
                          scan=ScanRecord(cloud, measured, measures, frame, transform, fit))
