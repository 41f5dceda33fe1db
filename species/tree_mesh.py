"""TreeMesh: a tree's bark and leaves as two triangle meshes with normals and UVs, exportable to GLB and OBJ.

Plain arrays in the world frame (Z up, metres); conversion to glTF's Y up happens only in the exporter.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Callable

import numpy as np

from .errors import TreefarmError
from .geometry.tangents import vertex_tangents
from .geometry.vectors import column_bounds

__all__ = ["MeshPart", "TreeMesh", "MeshError", "MESH_WRITERS", "quad_faces"]


class MeshError(TreefarmError):
    """A mesh's arrays are inconsistent (shape, index range, NaN), or a file format is unknown."""


# File writers by format name ("glb", "obj"): species.meshing registers them when `species` is imported, so the
# writers depend on this type and not the reverse.
MESH_WRITERS: dict[str, Callable[["TreeMesh"], Any]] = {}


def quad_faces(count: int) -> np.ndarray:
    """(2 count, 3) int64 faces of `count` quads stored four corners each, in order round the quad: two
    triangles (0, 1, 2), (0, 2, 3) per quad, counter-clockwise when the corners are."""
    return (np.array([[0, 1, 2], [0, 2, 3]])[None] + 4 * np.arange(count)[:, None, None]).reshape(-1, 3)


@dataclass(frozen=True, eq=False)
class MeshPart:
    """One triangle mesh with per-vertex attributes.

    vertices   : (V, 3) float32, metres, Z up.
    faces      : (F, 3) int32, counter-clockwise seen from outside (normals point out).
    normals    : (V, 3) float32, unit length.
    uvs        : (V, 2) float32, texture coordinates (v up, as in OBJ; the glTF writer flips v).
    attributes : extra per-vertex arrays by name, first axis V (for example `order`, uint8 branch order of
                 each bark vertex, which renderers use for masks and wind data).
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    uvs: np.ndarray
    attributes: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        v = np.ascontiguousarray(self.vertices, np.float32).reshape(-1, 3)
        f = np.ascontiguousarray(self.faces, np.int32).reshape(-1, 3)
        n = np.ascontiguousarray(self.normals, np.float32).reshape(-1, 3)
        uv = np.ascontiguousarray(self.uvs, np.float32).reshape(-1, 2)
        if len(n) != len(v) or len(uv) != len(v):
            raise MeshError(f"normals ({len(n)}) and uvs ({len(uv)}) must match vertices ({len(v)})")
        if len(f) and (f.min() < 0 or f.max() >= len(v)):
            raise MeshError(f"face indices must lie in [0, {len(v) - 1}]; got [{f.min()}, {f.max()}]")
        if not (np.isfinite(v).all() and np.isfinite(n).all() and np.isfinite(uv).all()):
            raise MeshError("vertices, normals or uvs contain NaN or infinity")
        attrs = {}
        for name, arr in self.attributes.items():
            arr = np.ascontiguousarray(arr)
            if len(arr) != len(v):
                raise MeshError(f"attribute {name!r} has {len(arr)} rows; vertices has {len(v)}")
            arr.setflags(write=False)
            attrs[name] = arr
        for arr in (v, f, n, uv):
            arr.setflags(write=False)
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)
        object.__setattr__(self, "normals", n)
        object.__setattr__(self, "uvs", uv)
        object.__setattr__(self, "attributes", attrs)

    @cached_property
    def tangents(self) -> np.ndarray:
        """(V, 4) float64 per-vertex tangents for normal maps (`species.geometry.vertex_tangents`), worked out
        once however many files are written from this part."""
        return vertex_tangents(self.vertices, self.normals, self.uvs, self.faces)

    @classmethod
    def empty(cls) -> "MeshPart":
        return cls(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 2)))

    @classmethod
    def concatenate(cls, parts: "list[MeshPart]") -> "MeshPart":
        """The parts as one, in order (faces renumbered); the attributes every part has are kept."""
        offsets = np.cumsum([0] + [part.n_vertices for part in parts])
        names = set.intersection(*(set(part.attributes) for part in parts)) if parts else set()
        return cls(np.concatenate([p.vertices for p in parts]), np.concatenate([p.faces + o for p, o in zip(parts, offsets)]),
                   np.concatenate([p.normals for p in parts]), np.concatenate([p.uvs for p in parts]),
                   {name: np.concatenate([p.attributes[name] for p in parts]) for name in sorted(names)})

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def n_faces(self) -> int:
        return len(self.faces)

    @cached_property
    def face_corners(self) -> np.ndarray:
        """(F, 3, 3) float64 metres, the corners of each face: gathered once for the many passes that project a
        tree's faces (twig cards fitted and pressed flat for every candidate level)."""
        corners = self.vertices.astype(np.float64)[self.faces]
        corners.setflags(write=False)
        return corners

    @cached_property
    def face_centroids(self) -> np.ndarray:
        """(F, 3) float64 metres, the mean of each face's corners."""
        centroids = self.face_corners.mean(axis=1)
        centroids.setflags(write=False)
        return centroids

    @cached_property
    def face_areas(self) -> np.ndarray:
        """(F,) float32, square metres."""
        tri = self.vertices[self.faces]
        return 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)

    def to_trimesh(self):
        """A `trimesh.Trimesh` sharing these arrays (no processing, so vertex order is kept)."""
        import trimesh

        return trimesh.Trimesh(vertices=self.vertices, faces=self.faces, vertex_normals=self.normals,
                               visual=trimesh.visual.TextureVisuals(uv=self.uvs), process=False)


@dataclass(frozen=True, eq=False)
class TreeMesh:
    """A meshed tree: bark and leaves kept apart (they get different materials and render passes).

    bark, leaves : MeshPart each; leaves may be empty.
    bark_color, leaf_color : (3,) float, linear RGB in [0, 1], base colours the textures are built around.
    name : used for node and mesh names in exported files.
    """

    bark: MeshPart
    leaves: MeshPart
    bark_color: tuple[float, float, float] = (0.36, 0.27, 0.19)
    leaf_color: tuple[float, float, float] = (0.24, 0.45, 0.14)
    name: str = "tree"

    @property
    def n_vertices(self) -> int:
        return self.bark.n_vertices + self.leaves.n_vertices

    @property
    def n_faces(self) -> int:
        return self.bark.n_faces + self.leaves.n_faces

    @cached_property
    def bounds(self) -> np.ndarray:
        """(2, 3) float32, min and max corner over bark and leaves."""
        return np.stack(column_bounds(np.concatenate([self.bark.vertices, self.leaves.vertices])))

    def export(self, file_format: str, **options) -> Any:
        """The tree written in `file_format` (a `MESH_WRITERS` name); `options` go to that writer."""
        if file_format not in MESH_WRITERS:
            raise MeshError(f"mesh file format {file_format!r} is unknown: allowed {', '.join(sorted(MESH_WRITERS))}")
        return MESH_WRITERS[file_format](self, **options)

    def to_glb(self, transform=None, extras: dict | None = None, compress_level: int = 9) -> bytes:
        """A binary glTF 2.0 file: Y up, two named meshes (bark, leaves) with textured PBR materials.

        transform : optional (4, 4) Z-up matrix placing the tree in a world frame (the root node's matrix);
        extras : optional JSON-able dict kept on the root node (`species.meshing.tree_mesh_to_glb`);
        compress_level : the texture PNGs' zlib level (9 the smallest files, lower levels faster).
        """
        return self.export("glb", transform=transform, extras=extras, compress_level=compress_level)

    def to_obj(self, compress_level: int = 9) -> dict[str, bytes]:
        """OBJ text, its MTL and the texture PNGs (at zlib level `compress_level`), by file name (`<name>.obj`,
        `<name>.mtl`, ...)."""
        return self.export("obj", compress_level=compress_level)
