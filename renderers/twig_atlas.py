"""The twig cards' atlas rendered from LOD0's own small branches and leaves with the farm's depth renderer: which
texels are bark or leaf, their tangent-space normals, and the per-season albedo with alpha.

In: a `species.studio.twig_cards.TwigAtlas`, LOD0's coverage tree (leaf cards cut to their tile's opaque share)
and the process's CoverageRenderer. Out: `TwigAtlasImage`, and the alpha-tested coverage of a level's cards.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from species.studio.twig_cards import TwigAtlas
from species.tree_mesh import MeshPart, TreeMesh, quad_faces

from .camera import Camera
from .maps import LEAVES, PartDepths, combine_parts, mask_albedo, tangent_space_normals

__all__ = ["TwigAtlasImage", "render_twig_atlas", "twig_atlas_texels", "TWIG_ATLAS_MAX_TEXELS",
           "TWIG_TEXELS_PER_TRIANGLE"]

# The atlas holds at most TWIG_TEXELS_PER_TRIANGLE texels per LOD0 triangle, at least 128 x 128 and at most
# TWIG_ATLAS_MAX_TEXELS; beyond it the levels' texels grow (`TwigAtlas.pack`). Its images then stay in proportion to the
# asset's geometry (docs/performance.md: their share of the GLB), while the crossed cards of a dense crown keep about
# a texel per screen pixel (a fixed 512 x 512 atlas coarsens them; docs/library.md).
TWIG_ATLAS_MAX_TEXELS = 1024 * 1024
TWIG_TEXELS_PER_TRIANGLE = 40
_MIN_TEXELS = 128 * 128


def twig_atlas_texels(lod0_triangles: int) -> int:
    """The most texels a twig atlas may hold for an asset whose LOD0 has `lod0_triangles` triangles."""
    return int(min(TWIG_ATLAS_MAX_TEXELS, max(_MIN_TEXELS, TWIG_TEXELS_PER_TRIANGLE * int(lod0_triangles))))


@dataclass(frozen=True, eq=False)
class TwigAtlasImage:
    """A rendered twig atlas.

    layout : the TwigAtlas it was rendered from.
    mask   : (H, W) uint8, 0 empty, 1 bark, 2 leaf.
    normal : (ceil(H / 2), ceil(W / 2), 3) uint8 tangent-space normals (+x along u, +y image up, +z toward the
             viewer), every second texel of the atlas's: the material samples it through the same UVs.
    """

    layout: TwigAtlas
    mask: np.ndarray
    normal: np.ndarray

    @property
    def opaque(self) -> np.ndarray:
        """(H, W) bool, texels an alpha test at 0.5 keeps (with leaves)."""
        return self.mask > 0

    def opaque_runs(self, level: int) -> MeshPart:
        """The opaque texels of `layout.levels[level]`'s cards as world-space quads, one per run of opaque texels
        along an atlas row (two triangles each): a pixel centre falls in them exactly where an alpha test at 0.5
        with nearest-texel sampling keeps the card, so opaque depth-only passes measure the cards as drawn.
        Worked out once per level (the fit and the quality figures both draw them)."""
        return self._level_runs[level]

    @cached_property
    def _level_runs(self) -> tuple[MeshPart, ...]:
        return tuple(self._runs(level) for level in range(len(self.layout.levels)))

    def _runs(self, level: int) -> MeshPart:
        layout = self.layout
        card = layout.card_index
        drawn = np.zeros(len(layout.source) + 1, bool)  # the level's tiles (the last entry: between tiles)
        drawn[layout.source[layout.first[level]:layout.first[level + 1]]] = True
        keep = self.opaque & drawn[card]
        padded = np.pad(keep, ((0, 0), (1, 1)))
        starts = np.argwhere(padded[:, 1:-1] & ~padded[:, :-2])  # (row, column) where a run begins
        ends = np.argwhere(padded[:, 1:-1] & ~padded[:, 2:])  # and where it ends (row-major, so they pair up)
        rows, begin, end = starts[:, 0], starts[:, 1], ends[:, 1] + 1
        owner = card[rows, begin]
        edges = np.stack([np.stack([begin, rows + 1], 1), np.stack([end, rows + 1], 1),
                          np.stack([end, rows], 1), np.stack([begin, rows], 1)], axis=1).reshape(-1, 2)
        corners = layout.from_atlas(edges, np.repeat(owner, 4))
        faces = quad_faces(len(rows))
        normals = np.repeat(np.concatenate([cards.axes[:, 2] for cards in layout.levels])[owner], 4, axis=0)
        return MeshPart(corners, faces, normals, np.zeros((len(corners), 2)))

    def albedo(self, bark_color, leaf_color) -> np.ndarray:
        """(H, W, 4) uint8 sRGB + alpha: bark texels in `bark_color`, leaf texels in `leaf_color` (linear RGB in
        [0, 1]), or transparent when `leaf_color` is None (a bare season keeps the twigs only)."""
        return mask_albedo(self.mask, bark_color, leaf_color)


def render_twig_atlas(renderer, layout: TwigAtlas, lod0_cover: TreeMesh) -> TwigAtlasImage:
    """Render every card's LOD0 faces, pressed into its tile, in one orthographic view of the atlas: one depth
    pass for the bark and one for the leaves (`renderer`: the process's CoverageRenderer)."""
    width, height = layout.size
    placed = layout.atlas_tree(lod0_cover)
    depths = np.concatenate([placed.bark.vertices[:, 2], placed.leaves.vertices[:, 2]]).astype(np.float64)
    if len(depths) == 0:
        return TwigAtlasImage(layout, np.zeros((height, width), np.uint8), np.full((height, width, 3), (128, 128, 255),
                                                                                    np.uint8))
    near, far = float(depths.min()) - 1.0, float(depths.max()) + 1.0
    # Atlas space is already in texels: one unit per pixel, pixel centres at integer (column, row).
    camera = Camera(width, height, np.eye(3), np.eye(4), "orthographic", near, far, width / 2, height / 2,
                    name="twig_atlas")
    renderer.load_groups({"bark": (placed.bark.vertices, placed.bark.faces, False),
                          LEAVES: (placed.leaves.vertices, placed.leaves.faces, True)})
    parts = PartDepths({"bark": renderer.group_depth(camera, ("bark",)), LEAVES: renderer.group_depth(camera, (LEAVES,))})
    depth, mask, _ = combine_parts(parts)
    # The normals at half the atlas's resolution (a quarter of the file): shading needs less detail than alpha.
    # They are worked out from every second texel's depth, through the camera of that coarser grid.
    half = Camera(-(-width // 2), -(-height // 2), np.diag([0.5, 0.5, 1.0]), np.eye(4), "orthographic", near, far,
                  width / 2, height / 2, name="twig_atlas_normals")
    normal = tangent_space_normals(half, depth[::2, ::2], mask[::2, ::2] > 0)
    normal.flags.writeable = False  # made once, written into each file (a PNG cache may know it by identity)
    return TwigAtlasImage(layout, mask, normal)
