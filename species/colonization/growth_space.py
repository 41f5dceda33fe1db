"""Growth spaces for self-organizing growth: regions of space that bound a crown, and marker sampling in them.

In: a closed mesh, voxel or point occupancy, lobes, a revolved crown profile or front/back depth maps (metres,
Z up). Out: `contains(points) -> (P,) bool` and `sample_markers(...) -> (M, 3) float64` metres.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..errors import TreefarmError

__all__ = ["GrowthSpaceError", "GrowthSpace", "ProfileCrown", "SuperquadricLobe", "UnionSpace", "MeshSpace",
           "VoxelSpace", "PointSpace", "DepthMapCrown", "random_lobes", "PROFILE_SHAPES", "profile_crown"]

_PROBE_POINTS = 4096  # points drawn once to estimate a space's volume from its bounding box


class GrowthSpaceError(TreefarmError):
    """A growth space that cannot bound growth: empty, open (not watertight), or malformed arrays."""


def _points(points: np.ndarray) -> np.ndarray:
    points = np.asarray(points, np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise GrowthSpaceError(f"points must have shape (P, 3); got {points.shape}")
    return points


class GrowthSpace:
    """A region of space, metres, Z up. Subclasses set `bounds` ((2, 3) float64) and implement `_contains`."""

    bounds: np.ndarray

    def contains(self, points: np.ndarray) -> np.ndarray:
        """(P,) bool: which of `points` (P, 3) metres lie inside the space."""
        points = _points(points)
        inside = np.zeros(len(points), bool)
        lo, hi = self.bounds
        in_box = np.all((points >= lo) & (points <= hi), axis=1)
        if in_box.any():
            inside[in_box] = self._contains(points[in_box])
        return inside

    def _contains(self, points: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def sample_markers(self, density: float, max_count: int, rng: np.random.Generator) -> np.ndarray:
        """(M, 3) float64 metres: uniform markers inside the space.

        density   : markers per cubic metre; the count is density times the estimated volume,
        max_count : but at most this many (and at least one).
        """
        lo, hi = self.bounds
        box_volume = float(np.prod(hi - lo))
        probe = lo + (hi - lo) * rng.random((_PROBE_POINTS, 3))
        inside = probe[self.contains(probe)]
        fraction = len(inside) / _PROBE_POINTS
        if fraction == 0.0:
            raise GrowthSpaceError(f"growth space {self!r} looks empty: none of {_PROBE_POINTS} probe points "
                                   f"inside its bounds {lo.round(3).tolist()}..{hi.round(3).tolist()}")
        target = int(np.clip(round(density * fraction * box_volume), 1, max_count))
        batches = [inside]
        have = len(inside)
        while have < target:
            draw = int((target - have) / fraction * 1.2) + 64
            batch = lo + (hi - lo) * rng.random((draw, 3))
            batch = batch[self.contains(batch)]
            batches.append(batch)
            have += len(batch)
        return np.concatenate(batches)[:target]

    def volume_estimate(self, rng: np.random.Generator, samples: int = 20000) -> float:
        """Cubic metres, Monte Carlo over the bounding box."""
        lo, hi = self.bounds
        probe = lo + (hi - lo) * rng.random((samples, 3))
        return float(self.contains(probe).mean() * np.prod(hi - lo))


# ---------------------------------------------------------------- analytic shapes
@dataclass(eq=False)
class ProfileCrown(GrowthSpace):
    """A solid of revolution about the Z axis through (x, y): radius radii[k] at height z_bottom + k*dz.

    radii : (K,) float64 metres, K >= 2, sampled evenly from z_bottom to z_top; linear in between.
    """

    z_bottom: float
    z_top: float
    radii: np.ndarray
    centre_xy: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        self.radii = np.asarray(self.radii, np.float64)
        if self.radii.ndim != 1 or len(self.radii) < 2 or np.any(self.radii < 0) or not self.radii.max() > 0:
            raise GrowthSpaceError(f"profile radii must be K >= 2 values >= 0, one > 0; got {self.radii}")
        if not self.z_top > self.z_bottom:
            raise GrowthSpaceError(f"profile z_top {self.z_top} must be above z_bottom {self.z_bottom}")
        cx, cy = self.centre_xy
        r = float(self.radii.max())
        self.bounds = np.array([[cx - r, cy - r, self.z_bottom], [cx + r, cy + r, self.z_top]])

    def _contains(self, points: np.ndarray) -> np.ndarray:
        t = (points[:, 2] - self.z_bottom) / (self.z_top - self.z_bottom)
        allowed = np.interp(t, np.linspace(0, 1, len(self.radii)), self.radii)
        dx, dy = points[:, 0] - self.centre_xy[0], points[:, 1] - self.centre_xy[1]
        return dx * dx + dy * dy <= allowed * allowed


PROFILE_SHAPES = ("ellipsoid", "cone", "vase", "cylinder", "dome", "umbrella", "teardrop")


def profile_crown(shape: str, radius: float, height: float, base: float, samples: int = 33) -> ProfileCrown:
    """A named crown silhouette revolved about Z: `shape` in PROFILE_SHAPES, metres."""
    t = np.linspace(0.0, 1.0, samples)
    profiles = {
        "ellipsoid": np.sqrt(np.clip(1 - (2 * t - 1) ** 2, 0, 1)),
        "cone": 1.0 - t,                                  # conifer: widest at the bottom
        "vase": 0.25 + 0.75 * np.sqrt(t) * np.sqrt(np.clip(1 - (t - 0.15) ** 8, 0, 1)),
        "cylinder": np.where((t > 0.02) & (t < 0.98), 1.0, 0.6),
        "dome": np.sqrt(np.clip(1 - t ** 2, 0, 1)),       # flat bottom, round top
        "umbrella": np.sqrt(np.clip(1 - ((t - 0.6) / 0.6) ** 2, 0, 1)),  # flat, wide top
        "teardrop": np.sqrt(np.clip(1 - (2 * t - 1) ** 2, 0, 1)) * (1.15 - 0.5 * t),
    }
    if shape not in profiles:
        raise GrowthSpaceError(f"unknown crown profile {shape!r}; known: {', '.join(PROFILE_SHAPES)}")
    radii = profiles[shape]
    return ProfileCrown(base, base + height, radius * radii / radii.max())


@dataclass(eq=False)
class SuperquadricLobe(GrowthSpace):
    """|x'/a|^e + |y'/b|^e + |z'/c|^e <= 1 in the lobe's frame (turned by `yaw` radians about Z).

    e = 2 is an ellipsoid; larger is boxier, smaller is pointier. centre (3,), radii (3,) metres.
    """

    centre: np.ndarray
    radii: np.ndarray
    exponent: float = 2.0
    yaw: float = 0.0

    def __post_init__(self) -> None:
        self.centre = np.asarray(self.centre, np.float64).reshape(3)
        self.radii = np.asarray(self.radii, np.float64).reshape(3)
        if np.any(self.radii <= 0) or not self.exponent > 0:
            raise GrowthSpaceError(f"lobe radii {self.radii} and exponent {self.exponent} must be > 0")
        reach = np.full(3, np.linalg.norm(self.radii[:2]))
        reach[2] = self.radii[2]
        self.bounds = np.stack([self.centre - reach, self.centre + reach])

    def _local(self, points: np.ndarray) -> np.ndarray:
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        d = points - self.centre
        local = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)
        return local / self.radii

    def _contains(self, points: np.ndarray) -> np.ndarray:
        return (np.abs(self._local(points)) ** self.exponent).sum(axis=1) <= 1.0

    def to_mesh(self, subdivisions: int = 3):
        """A closed trimesh.Trimesh of the lobe surface (an icosphere pushed onto the superquadric)."""
        import trimesh

        sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
        u = np.asarray(sphere.vertices, np.float64)
        scale = (np.abs(u) ** self.exponent).sum(axis=1) ** (-1.0 / self.exponent)
        local = u * scale[:, None] * self.radii
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        world = np.stack([c * local[:, 0] - s * local[:, 1], s * local[:, 0] + c * local[:, 1], local[:, 2]], 1)
        return trimesh.Trimesh(world + self.centre, np.asarray(sphere.faces), process=False)


@dataclass(eq=False)
class UnionSpace(GrowthSpace):
    """The union of several growth spaces (e.g. the lobes of a crown)."""

    parts: tuple

    def __post_init__(self) -> None:
        self.parts = tuple(self.parts)
        if not self.parts or not all(isinstance(p, GrowthSpace) for p in self.parts):
            raise GrowthSpaceError("a union needs at least one GrowthSpace part")
        self.bounds = np.stack([np.min([p.bounds[0] for p in self.parts], axis=0),
                                np.max([p.bounds[1] for p in self.parts], axis=0)])

    def _contains(self, points: np.ndarray) -> np.ndarray:
        inside = np.zeros(len(points), bool)
        for part in self.parts:  # a handful of lobes, each call vectorized over the points
            inside |= part.contains(points)
        return inside


def random_lobes(rng: np.random.Generator, count: int, radius: float, height: float, base: float,
                 exponent_range: tuple[float, float] = (2.0, 2.0)) -> UnionSpace:
    """A union of `count` random superquadric lobes filling a crown `radius` wide and `height` tall above `base`.

    The first lobe sits on the trunk axis, so the bole always reaches the crown. Metres.
    """
    lobes = []
    for k in range(count):  # loop over a handful of lobes, not markers
        size = rng.uniform(0.45, 0.75, 3) * np.array([radius, radius, height / 2])
        if k == 0:
            centre = np.array([0.0, 0.0, base + size[2]])
        else:
            angle, reach = rng.uniform(0, 2 * np.pi), rng.uniform(0.2, 0.55) * radius
            z = rng.uniform(base + size[2], max(base + size[2], base + height - size[2]))
            centre = np.array([reach * np.cos(angle), reach * np.sin(angle), z])
        lobes.append(SuperquadricLobe(centre, size, float(rng.uniform(*exponent_range)),
                                      float(rng.uniform(0, np.pi))))
    return UnionSpace(tuple(lobes))


# ---------------------------------------------------------------- meshes
class MeshSpace(GrowthSpace):
    """The inside of a closed triangle mesh (vertices (V, 3) metres, faces (F, 3) int).

    Containment by ray parity along +Z; triangles are bucketed on an XY grid so each point tests only the
    few triangles above its grid cell (no rtree needed).
    """

    def __init__(self, mesh=None, *, vertices=None, faces=None):
        if mesh is not None:
            vertices, faces = mesh.vertices, mesh.faces
        vertices = np.asarray(vertices, np.float64)
        faces = np.asarray(faces, np.int64)
        if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3 or not len(faces):
            raise GrowthSpaceError("a mesh growth space needs vertices (V, 3) and faces (F, 3), F > 0")
        edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
        _, uses = np.unique(edges, axis=0, return_counts=True)
        if np.any(uses != 2):
            raise GrowthSpaceError(f"the growth-space mesh is not closed: {int(np.sum(uses != 2))} edges are not "
                                   "shared by exactly two faces (a watertight mesh is required)")
        self.triangles = vertices[faces]  # (F, 3, 3)
        self.bounds = np.stack([vertices.min(axis=0), vertices.max(axis=0)])
        lo, hi = self.bounds[:, :2]
        self._grid = int(np.clip(np.sqrt(len(faces)), 1, 256))
        self._cell = np.maximum((hi - lo) / self._grid, 1e-12)
        tri_lo = np.floor((self.triangles[:, :, :2].min(axis=1) - lo) / self._cell).astype(np.int64)
        tri_hi = np.floor((self.triangles[:, :, :2].max(axis=1) - lo) / self._cell).astype(np.int64)
        tri_lo, tri_hi = np.clip(tri_lo, 0, self._grid - 1), np.clip(tri_hi, 0, self._grid - 1)
        span = tri_hi - tri_lo + 1
        per_tri = span[:, 0] * span[:, 1]
        tri = np.repeat(np.arange(len(faces)), per_tri)
        k = np.arange(len(tri)) - np.repeat(np.cumsum(per_tri) - per_tri, per_tri)
        cx = tri_lo[tri, 0] + k % span[tri, 0]
        cy = tri_lo[tri, 1] + k // span[tri, 0]
        cell = cx * self._grid + cy
        order = np.argsort(cell, kind="stable")
        self._cell_tris = tri[order]
        self._cell_offsets = np.searchsorted(cell[order], np.arange(self._grid * self._grid + 1))

    def _contains(self, points: np.ndarray) -> np.ndarray:
        ij = np.clip(np.floor((points[:, :2] - self.bounds[0, :2]) / self._cell).astype(np.int64), 0, self._grid - 1)
        cell = ij[:, 0] * self._grid + ij[:, 1]
        start, stop = self._cell_offsets[cell], self._cell_offsets[cell + 1]
        count = stop - start
        point = np.repeat(np.arange(len(points)), count)
        tri = self._cell_tris[np.repeat(start - np.cumsum(count) + count, count) + np.arange(count.sum())]
        a, b, c = (self.triangles[tri, i] for i in range(3))
        p = points[point]
        v0, v1, v2 = b - a, c - a, p - a
        den = v0[:, 0] * v1[:, 1] - v1[:, 0] * v0[:, 1]
        ok = np.abs(den) > 1e-18
        den = np.where(ok, den, 1.0)
        u = (v2[:, 0] * v1[:, 1] - v1[:, 0] * v2[:, 1]) / den
        w = (v0[:, 0] * v2[:, 1] - v2[:, 0] * v0[:, 1]) / den
        # Half-open barycentric test so a ray through a shared edge counts once.
        hit = ok & (u >= 0) & (w >= 0) & (u + w < 1)
        z = a[:, 2] + u * v0[:, 2] + w * v1[:, 2]
        crossings = np.bincount(point[hit & (z > p[:, 2])], minlength=len(points))
        return crossings % 2 == 1

    def __repr__(self) -> str:
        return f"MeshSpace(faces={len(self.triangles)})"


# ---------------------------------------------------------------- occupancy
class VoxelSpace(GrowthSpace):
    """Occupied voxels: occupancy (X, Y, Z) bool, voxel (i, j, k) spans origin + [i, i+1) * voxel_size."""

    def __init__(self, occupancy: np.ndarray, origin, voxel_size: float):
        self.occupancy = np.asarray(occupancy, bool)
        if self.occupancy.ndim != 3 or not self.occupancy.any():
            raise GrowthSpaceError(f"voxel occupancy must be a non-empty (X, Y, Z) bool grid; got "
                                   f"shape {self.occupancy.shape} with {int(self.occupancy.sum())} voxels set")
        if not voxel_size > 0:
            raise GrowthSpaceError(f"voxel_size must be > 0 metres; got {voxel_size}")
        self.origin = np.asarray(origin, np.float64).reshape(3)
        self.voxel_size = float(voxel_size)
        self.bounds = np.stack([self.origin, self.origin + np.array(self.occupancy.shape) * self.voxel_size])

    def _contains(self, points: np.ndarray) -> np.ndarray:
        ijk = np.floor((points - self.origin) / self.voxel_size).astype(np.int64)
        ijk = np.minimum(ijk, np.array(self.occupancy.shape) - 1)
        return self.occupancy[ijk[:, 0], ijk[:, 1], ijk[:, 2]]


class PointSpace(GrowthSpace):
    """Everything within `radius` metres of a point cloud points (P, 3) metres (e.g. a scanned crown)."""

    def __init__(self, points: np.ndarray, radius: float):
        points = _points(points)
        if not len(points) or not radius > 0:
            raise GrowthSpaceError(f"a point growth space needs points and a radius > 0; got {len(points)} points, "
                                   f"radius {radius}")
        self.points, self.radius = points, float(radius)
        self._tree = cKDTree(points)
        self.bounds = np.stack([points.min(axis=0) - radius, points.max(axis=0) + radius])

    def _contains(self, points: np.ndarray) -> np.ndarray:
        distance, _ = self._tree.query(points, k=1, distance_upper_bound=self.radius * (1 + 1e-9))
        return np.isfinite(distance)


class DepthMapCrown(GrowthSpace):
    """A crown from orthographic front and back depth maps, the form a sketch reconstruction produces.

    The camera looks along +Y. front, back : (H, W) float in [0, 1], 1 = background; a value d means
    y = y_near + d * (y_far - y_near) metres. Column 0 is x = extent[0], the last column x = extent[1];
    row 0 is z = extent[3] (top), the last row z = extent[2]. A point is inside when its pixel is
    foreground and its y lies between the front and back depth there.
    """

    def __init__(self, front: np.ndarray, back: np.ndarray, extent, depth_range):
        self.front, self.back = np.asarray(front, np.float64), np.asarray(back, np.float64)
        if self.front.ndim != 2 or self.front.shape != self.back.shape:
            raise GrowthSpaceError(f"front and back depth maps must be (H, W) of one shape; got "
                                   f"{self.front.shape} and {self.back.shape}")
        self.extent = np.asarray(extent, np.float64).reshape(4)
        self.depth_range = np.asarray(depth_range, np.float64).reshape(2)
        self.foreground = (self.front < 1.0) & (self.back < 1.0) & (self.back >= self.front)
        if not self.foreground.any():
            raise GrowthSpaceError("the depth maps have no foreground pixel (every pixel is 1 = background)")
        near, far = self.depth_range
        x0, x1, z0, z1 = self.extent
        self.bounds = np.array([[x0, near + self.front[self.foreground].min() * (far - near), z0],
                                [x1, near + self.back[self.foreground].max() * (far - near), z1]])

    @classmethod
    def from_silhouette(cls, silhouette: np.ndarray, extent, depth_range) -> "DepthMapCrown":
        """From a silhouette image (H, W, 3) float in [0, 1]: R front depth, G front-to-back gap, B mask
        (the renderers' "silhouette" output and the sketch cGAN's prediction); B < 0.5 is background."""
        silhouette = np.asarray(silhouette, np.float64)
        if silhouette.ndim != 3 or silhouette.shape[2] < 3:
            raise GrowthSpaceError(f"a silhouette must be (H, W, 3); got {silhouette.shape}")
        foreground = silhouette[..., 2] >= 0.5
        front = np.where(foreground, silhouette[..., 0], 1.0)
        back = np.where(foreground, np.minimum(silhouette[..., 0] + silhouette[..., 1], 1.0 - 1e-6), 1.0)
        return cls(front, back, extent, depth_range)

    def _contains(self, points: np.ndarray) -> np.ndarray:
        height, width = self.front.shape
        x0, x1, z0, z1 = self.extent
        col = np.clip(((points[:, 0] - x0) / (x1 - x0) * width).astype(np.int64), 0, width - 1)
        row = np.clip(((z1 - points[:, 2]) / (z1 - z0) * height).astype(np.int64), 0, height - 1)
        near, far = self.depth_range
        depth = (points[:, 1] - near) / (far - near)
        return self.foreground[row, col] & (depth >= self.front[row, col]) & (depth <= self.back[row, col])
