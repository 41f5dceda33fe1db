"""Octahedral impostors: a hemi-octahedral atlas of orthographic views of a tree over the upper hemisphere, one quad.
In: a TreeMesh (LOD0), frames per side and a tile size; out: `OctahedralAtlas` (atlas, quad, layout, silhouette).

The frames: frame (gx, gy), gx, gy in 0..N-1, is the orthographic view of the tree from the unit direction d
(toward the camera, Z up) whose hemi-octahedral point is (ox, oy) = (2 gx / (N - 1) - 1, 2 gy / (N - 1) - 1):
px = (ox + oy) / 2, py = (oy - ox) / 2, d = normalise(px, py, 1 - |px| - |py|). The square's edge is the horizon,
its centre the zenith, its corners +X (1, 1), -Y (1, -1), -X (-1, -1) and +Y (-1, 1). A frame's image right is
normalise(cross(-d, +Z)) (+X where d is +Z), its image up cross(right, -d). Its tile spans the tree's bounding
cylinder about `centre` (half width w across the vertical axis, half height h) as that frame sees it: [-w, w]
along right, [-e, e] along up with e = w |d_z| + h sqrt(1 - d_z^2) (`frame_extents`), so a tall narrow tree gets
fine texels across and a wide one both ways. The atlas holds frame (gx, gy) at tile column gx, tile row gy from
the top, N x N tiles of T px.

Drawing: the quad faces the camera, spanning the bounding sphere, [-radius, radius], about the centre; a view
direction picks the three frames of the grid triangle holding its hemi-octahedral point (barycentric weights),
each sampled where the pixel's ray crosses that frame's plane (through the centre, normal d), and the blended
alpha is tested at 0.5. The wind example's shader does this; `OctahedralAtlas.coverage` casts the same rays in
numpy.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from species.tree_mesh import MeshPart, TreeMesh, quad_faces

from .camera import Camera
from .gl_coverage import CoverageRenderer
from .impostor import ImpostorError, atlas_tile, pixel_rays, plane_coordinates

__all__ = ["OctahedralAtlas", "render_octahedral_impostor", "octahedral_encode", "octahedral_decode",
           "frame_directions", "frame_axes", "frame_extents", "frame_weights", "between_frame_azimuths",
           "OCTAHEDRAL_FRAMES", "FRAMES_RANGE", "MAX_ATLAS_PX", "MAPPING"]

OCTAHEDRAL_FRAMES = 12  # frames per side by default: horizon frames 5.2 to 10.4 deg apart in azimuth
FRAMES_RANGE = (4, 32)
MAX_ATLAS_PX = 1024  # atlas side limit (frames x tile), a texture every engine and WebGL device takes
MAPPING = "hemi-octahedral"
# The bounding cylinder and sphere are the tree's farthest vertices from the box centre, plus this margin.
_BOUNDS_MARGIN = 1.02
_UP = np.array([0.0, 0.0, 1.0])
# The quad a static viewer shows faces the view from azimuth 0 (from -Y, world X to the image right).
_STATIC_DIRECTION = np.array([0.0, -1.0, 0.0])


def octahedral_encode(directions: np.ndarray) -> np.ndarray:
    """(M, 2) float64 hemi-octahedral points in [-1, 1]^2 of directions (M, 3) (any length, Z up); directions
    below the horizon are taken onto it (z = 0), and straight down onto the zenith."""
    d = np.asarray(directions, np.float64).reshape(-1, 3).copy()
    d[:, 2] = np.maximum(d[:, 2], 0.0)
    norm = np.abs(d).sum(axis=1)
    flat = norm <= 1e-12
    d[flat] = _UP
    d /= np.where(flat, 1.0, norm)[:, None]
    return np.stack([d[:, 0] - d[:, 1], d[:, 0] + d[:, 1]], axis=1)


def octahedral_decode(points: np.ndarray) -> np.ndarray:
    """(M, 3) float64 unit directions (Z up, z >= 0) of hemi-octahedral points (M, 2) in [-1, 1]^2."""
    o = np.clip(np.asarray(points, np.float64).reshape(-1, 2), -1.0, 1.0)
    px, py = 0.5 * (o[:, 0] + o[:, 1]), 0.5 * (o[:, 1] - o[:, 0])
    d = np.stack([px, py, 1.0 - np.abs(px) - np.abs(py)], axis=1)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def frame_directions(frames: int) -> np.ndarray:
    """(N, N, 3) float64 unit directions toward each frame's camera, indexed [gy, gx] (module docstring)."""
    grid = 2.0 * np.arange(frames) / (frames - 1) - 1.0
    oy, ox = np.meshgrid(grid, grid, indexing="ij")
    return octahedral_decode(np.stack([ox.ravel(), oy.ravel()], axis=1)).reshape(frames, frames, 3)


def frame_axes(directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Image right and up (both (..., 3) float64 unit) of views from unit directions (..., 3) toward the camera:
    right = normalise(cross(-d, +Z)), +X for a view straight down; up = cross(right, -d)."""
    d = np.asarray(directions, np.float64)
    right = np.cross(-d, _UP)
    length = np.linalg.norm(right, axis=-1, keepdims=True)
    right = np.where(length > 1e-9, right / np.maximum(length, 1e-12), [1.0, 0.0, 0.0])
    return right, np.cross(right, -d)


def frame_extents(directions: np.ndarray, half_width: float, half_height: float) -> np.ndarray:
    """(..., 2) float64 metres: half the width and height a frame's tile spans (along its image right and up) for
    views from unit directions (..., 3), the bounding cylinder (half width across the vertical axis, half
    height) seen from there."""
    d = np.asarray(directions, np.float64)
    across = np.abs(d[..., 2])
    return np.stack([np.full(across.shape, half_width),
                     half_width * across + half_height * np.sqrt(np.maximum(1.0 - across ** 2, 0.0))], axis=-1)


def frame_weights(directions: np.ndarray, frames: int) -> tuple[np.ndarray, np.ndarray]:
    """The three frames blended for each view direction (M, 3), and their weights: cells (M, 3, 2) int64
    (gx, gy) and weights (M, 3) float64 summing to 1, the barycentric weights of the direction's
    hemi-octahedral point in its grid triangle (each grid cell is split along its (1, 0)-(0, 1) diagonal)."""
    g = 0.5 * (octahedral_encode(directions) + 1.0) * (frames - 1)
    base = np.clip(np.floor(g), 0, frames - 2)
    f = g - base
    upper = f.sum(axis=1) > 1.0
    ex, ey = np.array([1, 0]), np.array([0, 1])
    first = np.where(upper[:, None], base + 1, base)
    cells = np.stack([first, base + ex, base + ey], axis=1).astype(np.int64)
    weights = np.where(upper[:, None], np.stack([f.sum(axis=1) - 1.0, 1.0 - f[:, 1], 1.0 - f[:, 0]], axis=1),
                       np.stack([1.0 - f.sum(axis=1), f[:, 0], f[:, 1]], axis=1))
    return cells, weights


def between_frame_azimuths(frames: int) -> tuple[float, ...]:
    """Azimuths (degrees, `renderers.camera` convention) of the horizon views halfway (in the mapping) between
    each two neighbouring horizon frames, 4 (N - 1) of them: where a view is farthest from the frames it
    blends, and an impostor's worst case at elevation 0."""
    t = 2.0 * (np.arange(frames - 1) + 0.5) / (frames - 1) - 1.0  # halfway along an edge of the square
    one = np.ones_like(t)
    edges = np.concatenate([np.stack(pair, axis=1) for pair in ((one, t), (-t, one), (-one, -t), (t, -one))])
    d = octahedral_decode(edges)
    azimuths = np.degrees(np.arctan2(d[:, 0], -d[:, 1])) % 360.0  # view_direction(a, 0) = (sin a, -cos a, 0)
    return tuple(float(a) for a in np.sort(azimuths))


@dataclass(frozen=True, eq=False)
class OctahedralAtlas:
    """An octahedral impostor (module docstring for the mapping and the atlas layout).

    albedo : (N T, N T, 4) uint8 sRGB + alpha (255 where the tree covers the texel, not grown).
    normal : (ceil(N T / 2),) * 2 + (3,) uint8 tangent-space normals of each frame (+x image right, +y image
             up, +z toward the frame's camera; flat off the tree), every other texel of the albedo's grid: the
             same layout at half the resolution (shading needs less detail than the alpha; a quarter of the file).
    centre : (3,) float64 metres, Z up, the tree's box centre.
    radius : metres, the bounding sphere's radius about the centre (the drawn quad's half side).
    half_width, half_height : metres, the bounding cylinder about the vertical axis through the centre (each
             frame's tile spans it as seen from the frame, `frame_extents`).
    frames : N, frames per side of the hemi-octahedral grid.
    tile   : T, pixels per frame side.
    """

    albedo: np.ndarray
    normal: np.ndarray
    centre: np.ndarray
    radius: float
    half_width: float
    half_height: float
    frames: int
    tile: int

    kind: ClassVar[str] = "octahedral"

    @property
    def static_frame(self) -> tuple[int, int]:
        """(gx, gy) of the frame the static quad shows: the view from azimuth 0 at the horizon (a corner)."""
        cells, weights = frame_weights(_STATIC_DIRECTION[None], self.frames)
        gx, gy = cells[0, int(np.argmax(weights[0]))]
        return int(gx), int(gy)

    def tile_origin(self, gx: int, gy: int) -> tuple[int, int]:
        """(row, column) of the top-left texel of frame (gx, gy) in the atlas."""
        return gy * self.tile, gx * self.tile

    def mesh(self) -> MeshPart:
        """The quad (4 vertices, 2 triangles), as a static viewer shows it: facing the view from azimuth 0 at the
        horizon, spanning what `static_frame`'s tile spans (the bounding cylinder from the front), UVs (v up, OBJ
        convention) into that tile, normals toward that view. A shader that turns it toward the camera and picks
        frames by view direction (the wind example's) takes only its corners' sides of the centre from it."""
        right, up = frame_axes(_STATIC_DIRECTION)
        width, height = frame_extents(_STATIC_DIRECTION, self.half_width, self.half_height)
        corners = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
        vertices = self.centre + width * corners[:, :1] * right + height * corners[:, 1:] * up
        gx, gy = self.static_frame
        n = self.frames
        uvs = np.stack([(gx + 0.5 * (corners[:, 0] + 1.0)) / n, 1.0 - (gy + 1.0 - 0.5 * (corners[:, 1] + 1.0)) / n],
                       axis=1)
        return MeshPart(vertices, quad_faces(1), np.tile(_STATIC_DIRECTION, (4, 1)), uvs)

    def layout(self) -> dict:
        """The layout the files record (GLB extras, USD custom data, asset.json): JSON-able, metres, Z up."""
        return {"kind": self.kind, "mapping": MAPPING, "frames": int(self.frames), "tile_px": int(self.tile),
                "atlas_px": int(self.frames * self.tile), "normal_px": int(self.normal.shape[0]),
                "centre_m": [float(v) for v in self.centre],
                "radius_m": float(self.radius), "half_width_m": float(self.half_width),
                "half_height_m": float(self.half_height), "up_axis": "Z", "static_frame": list(self.static_frame),
                "frame_direction": "frame (gx, gy) at tile column gx, tile row gy from the top views from "
                                   "normalise(px, py, 1 - |px| - |py|), px = (ox + oy) / 2, py = (oy - ox) / 2, "
                                   "(ox, oy) = (2 gx / (frames - 1) - 1, 2 gy / (frames - 1) - 1)",
                "frame_axes": "right = normalise(cross(-d, +Z)) (+X when d = +Z), up = cross(right, -d); a tile "
                              "spans [-w, w] along right and [-e, e] along up about centre_m, w = half_width_m, "
                              "e = half_width_m |d_z| + half_height_m sqrt(1 - d_z^2); the quad drawn spans "
                              "[-radius_m, radius_m] both ways, turned toward the camera",
                "blend": "the 3 frames of the grid triangle (cells split along the (1, 0)-(0, 1) diagonal) holding "
                         "the view's point, barycentric weights, each sampled where the ray crosses its plane "
                         "through centre_m; alpha test 0.5 on the blend"}

    def coverage(self, camera: Camera) -> np.ndarray:
        """(H, W) bool, the silhouette the impostor shows through `camera`, as the wind example's shader draws
        it: the quad turned toward the camera position, the three frames of the view direction (from the centre
        to the camera) sampled where each pixel's ray crosses their planes (nearest texel, alpha >= 128), their
        alphas blended by the frames' weights and kept at >= 0.5."""
        origin, direction = pixel_rays(camera)
        view = camera.position - self.centre
        view /= np.linalg.norm(view)
        r = self.radius
        right, up = frame_axes(view)
        x, y, valid = plane_coordinates(origin, direction, self.centre, view, right, up)
        on_quad = valid & (np.abs(x) <= r) & (np.abs(y) <= r)
        cells, weights = frame_weights(view[None], self.frames)
        opaque = self.albedo[..., 3] >= 128
        blended = np.zeros(len(origin))
        directions = frame_directions(self.frames)
        for (gx, gy), weight in zip(cells[0], weights[0]):  # three frames, each over every pixel at once
            if weight <= 0.0:
                continue
            d = directions[gy, gx]
            frame_right, frame_up = frame_axes(d)
            fx, fy, crosses = plane_coordinates(origin, direction, self.centre, d, frame_right, frame_up)
            width, height = frame_extents(d, self.half_width, self.half_height)
            col = np.floor(fx * self.tile / (2.0 * width) + self.tile / 2).astype(np.int64)
            row = np.floor(-fy * self.tile / (2.0 * height) + self.tile / 2).astype(np.int64)
            inside = crosses & (col >= 0) & (col < self.tile) & (row >= 0) & (row < self.tile)
            r0, c0 = self.tile_origin(int(gx), int(gy))
            hit = np.zeros(len(origin))
            hit[inside] = opaque[r0 + row[inside], c0 + col[inside]]
            blended += weight * hit
        return (on_quad & (blended >= 0.5)).reshape(camera.height, camera.width)


def _frame_camera(centre: np.ndarray, radius: float, extents: np.ndarray, direction: np.ndarray, tile: int,
                  name: str) -> Camera:
    """The orthographic camera of one frame: looking along -direction at the centre, image axes `frame_axes`,
    the tile spanning +-extents (2,) metres along them, depth the sphere of `radius`."""
    right, up = frame_axes(direction)
    distance = 2.0 * radius + 1.0
    rotation = np.stack([right, -up, -direction])  # OpenCV axes: x right, y down, z forward
    E = np.eye(4)
    E[:3, :3] = rotation
    E[:3, 3] = -rotation @ (centre + distance * direction)
    sx, sy = tile / (2.0 * extents)
    K = np.array([[sx, 0, (tile - 1) / 2], [0, sy, (tile - 1) / 2], [0, 0, 1]])
    return Camera(tile, tile, K, E, "orthographic", distance - radius * 1.01, distance + radius * 1.01,
                  float(extents[0]), float(extents[1]), name=name)


def render_octahedral_impostor(renderer: CoverageRenderer, tree: TreeMesh, frames: int = OCTAHEDRAL_FRAMES,
                               tile: int = 64) -> OctahedralAtlas:
    """Render a tree's octahedral impostor: frames x frames orthographic views of the whole tree (module
    docstring), each two depth-only passes (bark, leaves) of the process's CoverageRenderer, made into tiles by
    `renderers.impostor.atlas_tile` (albedo sRGB with alpha 255 on the coverage, tangent-space normals)."""
    if not FRAMES_RANGE[0] <= frames <= FRAMES_RANGE[1]:
        raise ImpostorError(f"octahedral impostor frames {frames} is invalid: allowed {FRAMES_RANGE[0]}.."
                            f"{FRAMES_RANGE[1]} per side")
    if not 8 <= tile or frames * tile > MAX_ATLAS_PX:
        raise ImpostorError(f"octahedral impostor tile {tile} px is invalid with {frames} frames: allowed 8.."
                            f"{MAX_ATLAS_PX // frames} (an atlas of at most {MAX_ATLAS_PX} px square)")
    points = np.concatenate([tree.bark.vertices, tree.leaves.vertices]).astype(np.float64)
    if len(points) == 0:
        raise ImpostorError(f"tree {tree.name!r} has no vertices to make an impostor from")
    # Rounded as the files record them, so the shader's frames are the rendered ones to the last bit.
    centre = np.round(0.5 * (points.min(axis=0) + points.max(axis=0)), 6)
    relative = points - centre
    radius, half_width, half_height = (
        float(np.round(max(float(extent), 1e-3) * _BOUNDS_MARGIN, 6))
        for extent in (np.linalg.norm(relative, axis=1).max(), np.hypot(relative[:, 0], relative[:, 1]).max(),
                       np.abs(relative[:, 2]).max()))
    side = frames * tile
    albedo = np.zeros((side, side, 4), np.uint8)
    normal = np.zeros((side, side, 3), np.uint8)
    directions = frame_directions(frames)
    extents = frame_extents(directions, half_width, half_height)
    renderer.load(tree)
    for gy in range(frames):
        for gx in range(frames):
            camera = _frame_camera(centre, radius, extents[gy, gx], directions[gy, gx], tile,
                                   f"octahedral_{gx}_{gy}")
            rows, cols = slice(gy * tile, (gy + 1) * tile), slice(gx * tile, (gx + 1) * tile)
            albedo[rows, cols], normal[rows, cols] = atlas_tile(camera, renderer.part_depths(camera, False), tree)
    return OctahedralAtlas(albedo, np.ascontiguousarray(normal[::2, ::2]), centre, radius, half_width, half_height,
                           frames, tile)
