"""Far-distance impostors: a crossed-plane billboard whose albedo/normal/alpha atlas is rendered with the farm's
depth passes (`renderers.gl_coverage.CoverageRenderer`, the tree sliced among the planes), and the silhouette the
alpha-tested billboard shows (per pixel: by rasterising its triangles, or by casting rays at its planes). Leaf
cards are measured by the rule of `renderers.alpha_coverage` (cards shrunk to the opaque share of their alpha
tile); `renderers.silhouette_metric` compares the silhouettes.

In: TreeMesh (LOD0) and a tile size; out: `ImpostorAtlas` (atlas images, plane geometry, a MeshPart of <= 16
triangles), and (H, W) bool coverage masks of it through a camera.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from species.errors import TreefarmError
from species.geometry import plane_sectors
from species.tree_mesh import MeshPart, TreeMesh, quad_faces

from .alpha_coverage import pixel_mask, triangle_pixels
from .camera import Camera, look_at, view_direction
from .gl_coverage import CoverageRenderer
from .maps import LEAVES, PartDepths, combine_parts, mask_albedo, tangent_space_normals

__all__ = ["ImpostorAtlas", "ImpostorError", "render_impostor", "render_impostors", "impostor_coverage",
           "IMPOSTOR_PLANES", "AXIS_SHARE", "SECTOR_OVERLAP", "sector_groups", "atlas_tile", "pixel_rays",
           "plane_coordinates"]

# Vertical planes crossed at 180 / IMPOSTOR_PLANES degrees, two triangles each (16 triangles for 8): with 8, a
# view is never more than 11.25 deg off a plane, so no plane's silhouette shows narrower than cos 11.25 = 0.98.
IMPOSTOR_PLANES = 8
# Atlas tiles per row (planes fill rows of this many tiles).
_ATLAS_COLUMNS = 4
# The planes' square spans the tree's horizontal radius about the trunk and half height about the box centre, plus
# this margin.
_PLANE_MARGIN = 1.02
# The impostor's alpha is the rendered coverage, not grown: at the impostor's switch size a texel is about a
# screen pixel, and growing sparse crowns (conifer branch tips, isolated clusters) by a texel each way inflates
# them beyond the tree's closed silhouette (docs/library.md, "Impostor"; `benchmarks/bench_impostor.py`). The
# library grows it only where that matches LOD0 better (`ImpostorAtlas.grown`, `farm.library.lod_fit`).
# Faces this close to the vertical axis (share of the planes' half side) go on every plane. Seen between two
# planes, the crown's middle would otherwise come only from the planes nearly edge-on to the view, whose texels
# it samples sparsely: a hole. Faces in this outer share of a sector, on either side, go on the neighbouring plane
# too, for the same reason; a wider overlap smears the crown across planes. Both chosen by least IoU at the
# impostor's switch size over the presets (docs/library.md, "Impostor"; `benchmarks/bench_impostor.py`).
AXIS_SHARE = 0.2
SECTOR_OVERLAP = 0.15


class ImpostorError(TreefarmError):
    """An impostor cannot be made (empty tree, tile size out of range)."""


@dataclass(frozen=True, eq=False)
class ImpostorAtlas:
    """A crossed-plane impostor.

    albedo  : (R T, C T, 4) uint8 sRGB + alpha (alpha 255 where the tree covers the texel), one tile per plane
              in rows of C = min(P, 4) tiles.
    normal  : (R T, C T, 3) uint8 tangent-space normals (+x along u, +y image up, +z toward the viewer).
    centre  : (3,) float64 metres, where the planes cross (on the trunk's mean axis, at the box's mid height).
    half    : metres, half side of every plane's square.
    azimuths: (P,) float64 degrees, each plane faces the camera of that azimuth.
    tile    : T, pixels per tile side.
    """

    albedo: np.ndarray
    normal: np.ndarray
    centre: np.ndarray
    half: float
    azimuths: np.ndarray
    tile: int

    kind: ClassVar[str] = "crossed"

    def layout(self) -> dict:
        """What the files record about the impostor beyond its mesh and atlas: nothing (the planes' geometry is
        their mesh, which any glTF viewer draws); `renderers.octahedral_impostor` has a layout to record."""
        return {}

    def coverage(self, camera: Camera) -> np.ndarray:
        """(H, W) bool, the silhouette the billboard (`mesh()`) shows through `camera`: its triangles cut by the
        atlas alpha (>= 128, the files' 0.5 cutoff), rasterised per pixel centre (`alpha_coverage`)."""
        return self.coverage_of(self.billboard_pixels(camera), camera)

    def billboard_pixels(self, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
        """The billboard's pixel centres through `camera` and the atlas texel each samples (`triangle_pixels`):
        the same for every atlas of the same planes and atlas size (`same_billboard`), whatever their alpha."""
        billboard = self.mesh()
        return triangle_pixels(camera, billboard.vertices, billboard.faces, billboard.uvs, self.albedo.shape[:2])

    def coverage_of(self, pixels: tuple[np.ndarray, np.ndarray], camera: Camera) -> np.ndarray:
        """`coverage(camera)` from `billboard_pixels(camera)` of this atlas or of one with the same billboard."""
        pixel, texel = pixels
        return pixel_mask(camera, pixel[(self.albedo[..., 3] >= 128).ravel()[texel]])

    def same_billboard(self, other: "ImpostorAtlas") -> bool:
        """Whether `other` has this atlas's planes (centre, half side, azimuths) and atlas size: the same mesh
        and UVs, so the same `billboard_pixels`."""
        return (self.albedo.shape == other.albedo.shape and self.tile == other.tile and self.half == other.half
                and np.array_equal(self.centre, other.centre) and np.array_equal(self.azimuths, other.azimuths))

    def grown(self, texels: int) -> "ImpostorAtlas":
        """This atlas with each tile's opaque texels grown by `texels` 4-neighbour steps, within the tile: a new
        texel takes the colour of the first opaque neighbour (left, right, up, down), its normal stays flat. What
        a sparse, thin-branched plant needs at the impostor's switch size, where its twigs fall between the texels
        a screen pixel samples (`farm.library.lod_fit.fit_impostor` chooses per asset)."""
        if isinstance(texels, bool) or not isinstance(texels, (int, np.integer)) or not 0 <= texels <= 8:
            raise ImpostorError(f"impostor alpha growth {texels!r} texels is invalid: allowed an integer in 0..8")
        albedo = self.albedo.copy()
        for plane in range(len(self.azimuths)):
            row, col = self.tile_origin(plane)
            tile = albedo[row:row + self.tile, col:col + self.tile]  # a view: grown in place
            for _ in range(int(texels)):
                opaque = tile[..., 3] >= 128
                source = tile.copy()
                for into, taken in (((slice(None), slice(1, None)), (slice(None), slice(None, -1))),
                                    ((slice(None), slice(None, -1)), (slice(None), slice(1, None))),
                                    ((slice(1, None), slice(None)), (slice(None, -1), slice(None))),
                                    ((slice(None, -1), slice(None)), (slice(1, None), slice(None)))):
                    fill = ~opaque[into] & (source[taken][..., 3] >= 128)
                    tile[into][fill] = source[taken][fill]
                    opaque[into] |= fill
        return dataclasses.replace(self, albedo=albedo)

    def plane_axes(self) -> tuple[np.ndarray, np.ndarray]:
        """(P, 3) right vectors (image u) and (P, 3) normals toward each plane's camera, float64."""
        directions = np.stack([view_direction(a, 0.0) for a in self.azimuths])
        right = np.cross(-directions, np.array([0.0, 0.0, 1.0]))
        right /= np.linalg.norm(right, axis=1, keepdims=True)
        return right, directions

    def tile_origin(self, plane: int) -> tuple[int, int]:
        """(row, column) of the top-left texel of a plane's tile in the atlas."""
        columns = self.albedo.shape[1] // self.tile
        return (plane // columns) * self.tile, (plane % columns) * self.tile

    def mesh(self) -> MeshPart:
        """The billboard: one two-triangle square per plane (single-sided geometry; the material is double-sided),
        UVs into its tile (v up, OBJ convention), normals toward each plane's camera."""
        right, normal = self.plane_axes()
        up = np.array([0.0, 0.0, 1.0])
        h = self.half
        corners_local = np.array([[-h, -h], [h, -h], [h, h], [-h, h]])  # (x along right, y up)
        vertices = (self.centre[None, None, :] + corners_local[None, :, 0, None] * right[:, None, :]
                    + corners_local[None, :, 1, None] * up[None, None, :])
        height, width = self.albedo.shape[:2]
        uvs = []
        for plane in range(len(self.azimuths)):
            row, col = self.tile_origin(plane)
            u0, u1 = col / width, (col + self.tile) / width
            v1, v0 = 1.0 - row / height, 1.0 - (row + self.tile) / height  # image rows run down, v runs up
            uvs.append([[u0, v0], [u1, v0], [u1, v1], [u0, v1]])
        return MeshPart(vertices.reshape(-1, 3), quad_faces(len(self.azimuths)), np.repeat(normal, 4, axis=0),
                        np.asarray(uvs, np.float64).reshape(-1, 2))


def _plane_frame(tree: TreeMesh) -> tuple[np.ndarray, float, float]:
    points = np.concatenate([tree.bark.vertices, tree.leaves.vertices]).astype(np.float64)
    if len(points) == 0:
        raise ImpostorError(f"tree {tree.name!r} has no vertices to make an impostor from")
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre = 0.5 * (lo + hi)
    order = tree.bark.attributes.get("order")
    if order is not None and (np.asarray(order) == 0).any():
        # The planes cross on the trunk: its faces near that axis go on every plane (`sector_groups`), and a
        # crossing anywhere else would draw them at a different place on each plane, a smear as wide as the
        # offset between views.
        centre[:2] = tree.bark.vertices[np.asarray(order) == 0, :2].astype(np.float64).mean(axis=0)
    rel = points - centre
    radius_xy = float(np.sqrt((rel[:, :2] ** 2).sum(axis=1)).max())
    half = max(radius_xy, 0.5 * float(hi[2] - lo[2])) * _PLANE_MARGIN
    reach = float(np.linalg.norm(rel, axis=1).max())
    return centre, max(half, 1e-3), max(reach, 1e-3)


def _plane_camera(centre: np.ndarray, half: float, reach: float, azimuth: float, tile: int) -> Camera:
    direction = view_direction(azimuth, 0.0)
    distance = 2.0 * reach + 1.0
    E = look_at(centre + distance * direction, centre)
    s = tile / (2 * half)
    K = np.array([[s, 0, (tile - 1) / 2], [0, s, (tile - 1) / 2], [0, 0, 1]])
    return Camera(tile, tile, K, E, "orthographic", distance - reach * 1.01, distance + reach * 1.01, half, half,
                  name=f"impostor_az{azimuth:05.1f}")


def _compact(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The vertices the faces use (in their order), and the faces renumbered into them; a mask and a running
    count, not a sort (np.unique sorts, once per group of every impostor)."""
    used = np.zeros(len(vertices), bool)
    used[faces.ravel()] = True
    rank = np.cumsum(used, dtype=np.int64) - 1
    return np.asarray(vertices, np.float32)[used], rank[faces].astype(np.int32)


def sector_groups(tree: TreeMesh, centre: np.ndarray, planes: int, axis_radius: float,
                  overlap: float = SECTOR_OVERLAP) -> dict[str, tuple[np.ndarray, np.ndarray, bool]]:
    """Faces grouped by the plane they are drawn on: "bark_p"/"leaves_p" hold the faces whose centroid lies in
    plane p's two azimuth sectors (within 90 / planes degrees of the plane's line, either side of the axis), and
    those in the outer `overlap` share of a neighbouring sector next to them; "bark_axis"/"leaves_axis" the faces
    within `axis_radius` of the vertical axis, drawn on every plane. Every face is in the axis group or in one or
    two plane groups. A trunk that leaves the axis goes by sector like the rest: on every plane, each plane would
    draw it at another place and a view between them would see it that many times over (an S-shaped trunk such
    as bonsai's)."""
    names = {"band0": "axis", **{f"band1_{plane}": str(plane) for plane in range(planes)}}
    return {f"{kind}_{names[band]}": group for key, group in _banded_groups(tree, centre, planes, [axis_radius],
                                                                             overlap).items()
            for kind, band in [key.split("_", 1)]}


def render_impostor(renderer: CoverageRenderer, tree: TreeMesh, tile: int = 128, planes: int = IMPOSTOR_PLANES,
                    axis_share: float = AXIS_SHARE, sector_overlap: float = SECTOR_OVERLAP) -> ImpostorAtlas:
    """Render a tree's impostor atlas: for each plane an orthographic view along its normal of the slice of the
    tree nearest that plane (`sector_groups`: the faces within 90 / planes degrees of azimuth of it, a margin of
    `sector_overlap` shared with its neighbours, the faces within `axis_share` of the planes' half side of the
    axis in every plane), giving albedo (bark or leaf colour by the rendered mask, sRGB), alpha 255
    on the rendered coverage and tangent-space normals (from the rendered depth). Slicing puts most of the crown on one plane only, so a view between planes sees the
    crown about once, not the union of every plane's whole view (which fills in a sparse crown). The slices are
    uploaded once, two depth-only passes (bark, leaves) per plane. `renderer` is the process's
    CoverageRenderer."""
    return render_impostors(renderer, tree, tile, planes, (axis_share,), sector_overlap)[0]


def render_impostors(renderer: CoverageRenderer, tree: TreeMesh, tile: int = 128, planes: int = IMPOSTOR_PLANES,
                     axis_shares=(AXIS_SHARE,), sector_overlap: float = SECTOR_OVERLAP) -> list[ImpostorAtlas]:
    """`render_impostor` for each of `axis_shares`, the faces uploaded once: in bands between the shares' axis
    radii, each band both whole (drawn on every plane by the shares whose axis holds it) and by sector."""
    if not 8 <= tile <= 2048:
        raise ImpostorError(f"impostor tile {tile} px is invalid: allowed 8..2048")
    if not 1 <= planes <= 8:
        raise ImpostorError(f"impostor planes {planes} is invalid: allowed 1..8 (at most 16 triangles)")
    centre, half, reach = _plane_frame(tree)
    azimuths = np.arange(planes) * (180.0 / planes)
    columns = min(planes, _ATLAS_COLUMNS)
    rows = -(-planes // columns)
    radii = sorted({float(share) * half for share in axis_shares})
    renderer.load_groups(_banded_groups(tree, centre, planes, radii, sector_overlap))
    atlases = []
    for share in axis_shares:
        inner = radii.index(float(share) * half) + 1  # the bands within this share's axis radius
        albedo = np.zeros((rows * tile, columns * tile, 4), np.uint8)
        normal = np.zeros((rows * tile, columns * tile, 3), np.uint8)
        normal[...] = (128, 128, 255)
        for plane, azimuth in enumerate(azimuths):
            camera = _plane_camera(centre, half, reach, float(azimuth), tile)
            parts = PartDepths({kind: renderer.group_depth(
                camera, [f"{kind}_band{band}" for band in range(inner)]
                + [f"{kind}_band{band}_{plane}" for band in range(inner, len(radii) + 1)])
                for kind in ("bark", LEAVES)})
            row, col = (plane // columns) * tile, (plane % columns) * tile
            albedo[row:row + tile, col:col + tile], normal[row:row + tile, col:col + tile] = atlas_tile(
                camera, parts, tree)
        atlases.append(ImpostorAtlas(albedo, normal, centre, half, azimuths.astype(np.float64), tile))
    return atlases


def _banded_groups(tree: TreeMesh, centre: np.ndarray, planes: int, radii: list[float],
                   overlap: float) -> dict[str, tuple[np.ndarray, np.ndarray, bool]]:
    """`sector_groups` for several axis radii at once (ascending): "bark_band{b}"/"leaves_band{b}" the faces
    whose distance from the axis lies in band b (within radii[0]; between radii[b - 1] and radii[b]; beyond the
    last), and "..._band{b}_{p}" those of them that plane p draws by sector (with the overlap). Drawn with the
    whole bands within a radius and the sector groups of the bands beyond it, a plane shows exactly the faces
    `sector_groups` gives it for that radius."""
    # Plane p's line in the ground plane is at angle line0 + p * 180 / planes (it turns with its azimuth).
    right = np.cross(-view_direction(0.0, 0.0), [0.0, 0.0, 1.0])
    line0 = np.degrees(np.arctan2(right[1], right[0]))
    groups = {}
    for kind, part in (("bark", tree.bark), (LEAVES, tree.leaves)):
        if part.n_faces == 0:
            continue
        centroid = part.vertices[part.faces].mean(axis=1).astype(np.float64) - centre
        angle = np.degrees(np.arctan2(centroid[:, 1], centroid[:, 0]))
        sector, neighbour, shared = plane_sectors(angle - line0, planes, overlap)
        distance = np.hypot(centroid[:, 0], centroid[:, 1])
        band = np.searchsorted(np.asarray(radii), distance, side="left")  # distance <= radii[b] -> band <= b
        for b in range(len(radii) + 1):
            within = band == b
            if b < len(radii):
                groups[f"{kind}_band{b}"] = (*_compact(part.vertices, part.faces[within]), kind == LEAVES)
            if b == 0:
                continue
            for index in range(planes):
                chosen = within & ((sector == index) | (shared & (neighbour == index)))
                groups[f"{kind}_band{b}_{index}"] = (*_compact(part.vertices, part.faces[chosen]),
                                                     kind == LEAVES)
    return groups


def atlas_tile(camera: Camera, parts: PartDepths, tree: TreeMesh) -> tuple[np.ndarray, np.ndarray]:
    """One impostor atlas tile from a view's bark and leaf depths (`parts`, both (T, T) metres through the
    orthographic `camera`): albedo (T, T, 4) uint8, the tree's bark or leaf colour in sRGB by the nearer part,
    alpha 255 on the covered texels (not grown), and normals (T, T, 3) uint8 in tangent space (+x along u, +y
    image up, +z toward the viewer; flat (128, 128, 255) off the tree), from the rendered depth."""
    depth, mask, _ = combine_parts(parts)
    return mask_albedo(mask, tree.bark_color, tree.leaf_color), tangent_space_normals(camera, depth, mask > 0)


def pixel_rays(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """The ray through each pixel centre, row by row: origins (H W, 3) and directions (H W, 3) float64, metres,
    world (a point at depth 1 m and the step to depth 2 m; not unit length)."""
    rows, cols = np.mgrid[0:camera.height, 0:camera.width]
    pixels = np.stack([cols.ravel(), rows.ravel()], axis=1).astype(np.float64)
    near_points = camera.unproject(pixels, np.full(len(pixels), 1.0))
    return near_points, camera.unproject(pixels, np.full(len(pixels), 2.0)) - near_points


def plane_coordinates(origin: np.ndarray, direction: np.ndarray, centre: np.ndarray, normal: np.ndarray,
                      right: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where rays (origins and directions (P, 3), metres) cross the plane through `centre` (3,) with `normal`
    (3,): coordinates x along `right` and y along `up` (both (3,) unit, in the plane), (P,) float64 metres from
    the centre, and (P,) bool, True where the ray crosses the plane (not parallel to it)."""
    denom = direction @ normal
    valid = np.abs(denom) > 1e-12
    t = np.where(valid, ((centre - origin) @ normal) / np.where(valid, denom, 1.0), 0.0)
    hit = origin + t[:, None] * direction - centre
    return hit @ right, hit @ up, valid


def impostor_coverage(atlas: ImpostorAtlas, camera: Camera) -> np.ndarray:
    """(H, W) bool, pixels whose ray hits an opaque texel (alpha >= 128) of any impostor plane: the silhouette
    an alpha-tested, double-sided billboard shows, cast exactly per pixel centre (nearest texel)."""
    h, w = camera.height, camera.width
    origin, direction = pixel_rays(camera)
    right, normal = atlas.plane_axes()
    up = np.array([0.0, 0.0, 1.0])
    s = atlas.tile / (2 * atlas.half)
    covered = np.zeros(len(origin), bool)
    alpha = atlas.albedo[..., 3] >= 128
    for plane in range(len(atlas.azimuths)):
        x, y, valid = plane_coordinates(origin, direction, atlas.centre, normal[plane], right[plane], up)
        col = np.floor(x * s + atlas.tile / 2).astype(np.int64)
        row = np.floor(-y * s + atlas.tile / 2).astype(np.int64)
        inside = valid & (col >= 0) & (col < atlas.tile) & (row >= 0) & (row < atlas.tile)
        r0, c0 = atlas.tile_origin(plane)
        hits = np.zeros(len(origin), bool)
        hits[inside] = alpha[r0 + row[inside], c0 + col[inside]]
        covered |= hits
    return covered.reshape(h, w)
