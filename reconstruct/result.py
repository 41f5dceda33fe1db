"""What every reconstruction method returns: `Reconstruction` (the tree, its mesh, the dictionary it grew with if
any, stage timings, intermediate maps, warnings) and, for the methods that read a point cloud or photos, the
`ScanRecord` of the cloud and what was measured in it, with the frame the files are written in."""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from species.skeleton import Skeleton
from species.tree_mesh import TreeMesh

from .clouds import PointCloud
from .qsm import write_branch_csv, write_qsm_csv, write_skeleton_ply
from .skeleton import CloudSkeleton

__all__ = ["Reconstruction", "ScanRecord"]

# A scan's GLB holds megabytes of measured geometry and is written once, by a command that should end soon after
# it: its two texture PNGs at zlib's fastest level, a few kilobytes more than the smallest (the same pixels).
SCAN_TEXTURE_LEVEL = 1


@dataclass(frozen=True, eq=False)
class ScanRecord:
    """The cloud a tree was reconstructed from and what was measured in it.

    cloud      : the points read (`reconstruct.clouds.PointCloud`: Z up, recentred, with the offset and up axis).
    measured   : the skeleton from the points alone, in the base frame (the trunk's base at the origin).
    measures   : its QSM measures (`reconstruct.qsm.qsm_measures` of the measured skeleton and the cloud's points,
                 plus "trunk_radius_fit_m"); in the GLB's extras and the `write(qsm_csv=)` table.
    frame      : "base" or "scan", the frame the files are written in; transform : (4, 4) float64 from the base
                 frame to the scan's own coordinates (the offset and up axis `read_cloud` took off, put back).
    fit        : the skeletonisation's record (trunk radius, spacing, points used, stage timings).
    provenance : where the cloud came from beyond the file ({"sfm": ...} for photos); goes in the GLB's extras.
    """

    cloud: PointCloud
    measured: Skeleton
    measures: dict
    frame: str
    transform: np.ndarray
    fit: CloudSkeleton
    provenance: dict = field(default_factory=dict)

    @property
    def base_points(self) -> np.ndarray:
        """(N, 3) float64: the cloud's points in the base frame, the skeleton's and the mesh's (its working frame
        less the measured root)."""
        root = self.cloud.up_rotation @ self.transform[:3, 3] - self.cloud.offset   # the transform's inverse
        return self.cloud.points.astype(np.float64) - root


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """A tree reconstructed by one method of `reconstruct.methods.METHODS`.

    method   : the method's name in the registry ("params", "sketch-depth", "two-view", "cloud", "photos").
    skeleton : the tree, metres, Z up, its base at the origin.
    mesh     : its bark and leaves (TreeMesh).
    params   : the parameter dictionary it grew with (params, sketch-depth), None for a method that grows none.
    timings  : seconds per stage, in the order they ran (each method's docstring names its stages).
    maps     : intermediate arrays and records by name (each method's docstring lists them); a method that traces
               or lifts main branches gives their nodes as "main_skeleton" (G, 3) float32 metres.
    warnings : what a user should know (a leaf-on cloud, photos SfM could not place).
    scan     : the cloud and what was measured in it, for the methods that read a point cloud or photos.
    """

    method: str
    skeleton: Skeleton
    mesh: TreeMesh
    params: dict | None = None
    timings: dict[str, float] = field(default_factory=dict)
    maps: dict[str, Any] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    scan: ScanRecord | None = None

    def _scan(self) -> ScanRecord:
        if self.scan is None:
            raise ValueError(f"a {self.method} reconstruction has no scan: the scan frame and its files are the "
                             "cloud and photos methods'")
        return self.scan

    def in_scan_frame(self) -> tuple[Skeleton, TreeMesh]:
        """The skeleton and the mesh moved by the scan's `transform` into its own coordinates (what a true tree the
        scan was sampled from is in)."""
        transform = self._scan().transform
        rotation, shift = transform[:3, :3], transform[:3, 3]

        def moved(points: np.ndarray) -> np.ndarray:
            return (points.astype(np.float64) @ rotation.T + shift).astype(np.float32)

        def moved_part(part):
            return replace(part, vertices=moved(part.vertices),
                           normals=(part.normals.astype(np.float64) @ rotation.T).astype(np.float32))

        leaves = (transform @ self.skeleton.leaves.astype(np.float64)).astype(np.float32)
        skeleton = replace(self.skeleton, positions=moved(self.skeleton.positions), leaves=leaves)
        mesh = replace(self.mesh, bark=moved_part(self.mesh.bark), leaves=moved_part(self.mesh.leaves))
        return skeleton, mesh

    @property
    def extras(self) -> dict:
        """The GLB's root-node extras: the frame, the scan's offset and up axis, the method and the measures."""
        scan = self._scan()
        return {"treefarm": {"method": self.method, **scan.provenance, "frame": scan.frame,
                             "source": scan.cloud.source,
                             "scan_offset_m": [float(v) for v in scan.cloud.offset], "scan_up": scan.cloud.up,
                             "base_in_scan_m": [float(v) for v in scan.transform[:3, 3]],
                             "measures": scan.measures}}

    def glb(self, *, timings: bool = False) -> bytes:
        """The mesh as GLB in the scan's frame, with `extras` on its root node; with `timings`, the stage timings
        too (`timings_s`, seconds), which differ from run to run, so the same inputs no longer give the same bytes."""
        scan = self._scan()
        extras = self.extras
        if timings:
            extras["treefarm"]["timings_s"] = {stage: round(float(s), 3) for stage, s in self.timings.items()}
        return self.mesh.to_glb(transform=None if scan.frame == "base" else scan.transform, extras=extras,
                                compress_level=SCAN_TEXTURE_LEVEL)

    def write(self, out: str | Path, *, skeleton_ply: str | Path | None = None, qsm_csv: str | Path | None = None,
              branches_csv: str | Path | None = None, timings: bool = False) -> None:
        """The GLB at `out` (with the stage timings in its extras when `timings`, see `glb`), and when asked the
        measured skeleton's PLY, its measures (`qsm_csv`: one row, `reconstruct.qsm.write_qsm_csv`) and its branch
        table (`branches_csv`); each file is written whole to a temporary name first, so a failure leaves no half
        file."""
        scan = self._scan()
        jobs = [(Path(out), lambda p: p.write_bytes(self.glb(timings=timings)))]
        if skeleton_ply is not None:
            if scan.frame == "base":
                jobs.append((Path(skeleton_ply), lambda p: write_skeleton_ply(scan.measured, p)))
            else:
                turned = _rotated(scan.measured, scan.transform[:3, :3])
                jobs.append((Path(skeleton_ply), lambda p: write_skeleton_ply(turned, p, offset=scan.transform[:3, 3])))
        if qsm_csv is not None:
            jobs.append((Path(qsm_csv), lambda p: write_qsm_csv(scan.measures, p, scan.cloud.source)))
        if branches_csv is not None:
            jobs.append((Path(branches_csv), lambda p: write_branch_csv(scan.measured, p)))
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
