"""Twig cluster cards: the branches a level of detail drops, each drawn as one textured card in the plane of its
own geometry (as SpeedTree's twig cards are), with its leaves, instead of being dropped or merged into a clump.

In: the Skeleton, its LOD0 TreeMesh, which branches a level keeps and how deep a dropped subtree may split into
cards. Out: `TwigCards` (card corners, the LOD0 faces each card stands for, those faces flattened onto the card,
which is what the card shows seen from anywhere), and `TwigAtlas`, the atlas layout of cards at a texel size.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..errors import TreefarmError
from ..skeleton import Skeleton
from ..tree_mesh import MeshPart, TreeMesh, quad_faces
from ..geometry.topology import depth_levels, node_depths
from .leaf_clusters import cluster_axes

__all__ = ["TwigCards", "TwigAtlas", "TwigCardError", "twig_labels", "twig_cards", "TWIG_PADDING_TEXELS",
           "TWIG_DEPTH_OFFSET"]

# Empty texels around each card's tile, so a sampled mip or a bilinear tap never reads its neighbour.
TWIG_PADDING_TEXELS = 2
# Atlas-space depth (texels) added so every flattened face lies in front of the atlas camera.
TWIG_DEPTH_OFFSET = 1.0e4
# Extra share of the card beyond its faces on each side (texel rounding is added on top).
_CARD_MARGIN = 0.02


class TwigCardError(TreefarmError):
    """Twig cards asked of branches that are not dropped, or an atlas too large for its texel size."""


def twig_labels(skeleton: Skeleton, kept_branch: np.ndarray, max_depth: int | None) -> np.ndarray:
    """(B,) int64 card per branch: -1 for kept branches; every dropped branch at most `max_depth` branchings below
    the kept branch its dropped subtree grows from gets a card of its own, deeper ones share their ancestor's at
    that depth (None: every dropped branch its own card; 0: one card per dropped subtree). Cards are numbered in
    branch order."""
    kept = np.asarray(kept_branch, bool)
    if kept.shape != (skeleton.n_branches,):
        raise TwigCardError(f"kept_branch of shape {kept.shape} is invalid: allowed ({skeleton.n_branches},)")
    parent = skeleton.branch_parent
    # Depth of each dropped branch below its subtree's root (the dropped branch whose parent is kept), settled
    # one branching depth at a time so every parent is done before its children.
    depth = np.where(kept, -1, 0)
    owner = np.where(kept, -1, np.arange(len(kept)))
    inner = ~kept & (parent >= 0) & ~kept[np.maximum(parent, 0)]
    for at in depth_levels(node_depths(parent)):
        at = at[inner[at]]
        depth[at] = depth[parent[at]] + 1
        if max_depth is not None:
            owner[at] = np.where(depth[at] > max_depth, owner[parent[at]], at)
    labels = np.full(len(kept), -1, np.int64)
    roots = np.unique(owner[owner >= 0])
    labels[owner >= 0] = np.searchsorted(roots, owner[owner >= 0])
    return labels


@dataclass(frozen=True, eq=False)
class TwigCards:
    """Cards standing for the dropped branches of one level.

    origin         : (C, 3) float64 metres, each card's corner at its (0, 0) texel.
    axes           : (C, 3, 3) float64, rows u (across the tile), v (up the tile), normal; right-handed.
    extent         : (C, 2) float64 metres along u and v.
    branch         : (C,) int64, the LOD0 branch each card's faces grow from nearest the trunk (wind follows it).
    bark_faces, leaf_faces : (F,) int64 indices of LOD0's bark / leaf faces each card stands for, and
    bark_card, leaf_card   : (F,) int64 their card.
    """

    origin: np.ndarray
    axes: np.ndarray
    extent: np.ndarray
    branch: np.ndarray
    bark_faces: np.ndarray
    bark_card: np.ndarray
    leaf_faces: np.ndarray
    leaf_card: np.ndarray

    def __len__(self) -> int:
        return len(self.origin)

    @cached_property
    def corners(self) -> np.ndarray:
        """(C, 4, 3) float64 metres: (0, 0), (u, 0), (u, v), (0, v) of each card."""
        du = self.axes[:, 0] * self.extent[:, :1]
        dv = self.axes[:, 1] * self.extent[:, 1:]
        o = self.origin
        return np.stack([o, o + du, o + du + dv, o + dv], axis=1)

    def flattened(self, lod0: TreeMesh) -> TreeMesh:
        """LOD0's faces of these cards, each pressed onto its card's plane: what an exact card texture shows from
        any direction (bark in `bark`, leaf cards in `leaves`; vertices (V, 3) float32 metres)."""
        parts = []
        for part, faces, card in ((lod0.bark, self.bark_faces, self.bark_card),
                                  (lod0.leaves, self.leaf_faces, self.leaf_card)):
            points = np.asarray(part.vertices, np.float64)[part.faces[faces]].reshape(-1, 3)
            card = np.repeat(card, 3)
            normal = self.axes[card, 2]
            offset = np.einsum("ij,ij->i", points - self.origin[card], normal)
            flat = (points - offset[:, None] * normal).astype(np.float32)
            parts.append(MeshPart(flat, np.arange(len(flat), dtype=np.int32).reshape(-1, 3),
                                  normal.astype(np.float32), np.zeros((len(flat), 2), np.float32)))
        return TreeMesh(bark=parts[0], leaves=parts[1], bark_color=lod0.bark_color, leaf_color=lod0.leaf_color,
                        name=f"{lod0.name}_twigs")


def twig_cards(skeleton: Skeleton, lod0: TreeMesh, labels: np.ndarray) -> TwigCards:
    """Cards for branch labels of `twig_labels`: each card lies in the plane of the two widest spreads of its LOD0
    faces (bark vertices of its branches, corners of their leaf cards) and spans them, plus a small margin."""
    labels = np.asarray(labels, np.int64)
    n = int(labels.max(initial=-1)) + 1
    bark_branch = np.asarray(lod0.bark.attributes["branch"], np.int64)[lod0.bark.faces[:, 0]]
    leaf_branch = skeleton.branch_id[np.asarray(lod0.leaves.attributes["node"], np.int64)[lod0.leaves.faces[:, 0]]] \
        if lod0.leaves.n_faces else np.zeros(0, np.int64)
    bark_card, leaf_card = labels[bark_branch], labels[leaf_branch]
    bark_faces, leaf_faces = np.flatnonzero(bark_card >= 0), np.flatnonzero(leaf_card >= 0)
    points = np.concatenate([lod0.bark.vertices[lod0.bark.faces[bark_faces]].reshape(-1, 3),
                             lod0.leaves.vertices[lod0.leaves.faces[leaf_faces]].reshape(-1, 3)]).astype(np.float64)
    point_card = np.concatenate([np.repeat(bark_card[bark_faces], 3), np.repeat(leaf_card[leaf_faces], 3)])
    if n and np.bincount(point_card, minlength=n).min() == 0:
        raise TwigCardError("a twig card has no LOD0 faces: its branches drew nothing")
    mean, axes = cluster_axes(points, point_card, n)
    # Rows: u along the principal axis, v along the second, normal along the least spread; right-handed.
    u, v = axes[:, :, 2], axes[:, :, 1]
    normal = np.cross(u, v)
    frame = np.stack([u, v, normal], axis=1)
    local = np.einsum("pj,pij->pi", points - mean[point_card], frame[point_card])
    low = np.full((n, 2), np.inf)
    high = np.full((n, 2), -np.inf)
    np.minimum.at(low, point_card, local[:, :2])
    np.maximum.at(high, point_card, local[:, :2])
    pad = _CARD_MARGIN * np.maximum(high - low, 1e-6)
    low, high = low - pad, high + pad
    origin = mean + np.einsum("ck,cki->ci", low, frame[:, :2])
    branch = np.full(n, np.iinfo(np.int64).max)
    np.minimum.at(branch, labels[labels >= 0], np.flatnonzero(labels >= 0))
    return TwigCards(origin, frame, high - low, branch, bark_faces, bark_card[bark_faces],
                     leaf_faces, leaf_card[leaf_faces])


@dataclass(frozen=True, eq=False)
class TwigAtlas:
    """Where each card of several levels lies in one atlas image, and the atlas-space geometry to render it from.

    levels : the TwigCards of each level, their cards numbered on end to end (card c of level k is
             `first[k] + c`).
    texel  : (C,) float64 metres per texel of each card.
    offset : (C, 2) int64 (column, row) of each tile's top-left texel; tiles are TWIG_PADDING_TEXELS larger than
             their card on every side.
    size   : (width, height) texels of the atlas.
    """

    levels: tuple
    texel: np.ndarray
    offset: np.ndarray
    size: tuple[int, int]

    @classmethod
    def pack(cls, levels, texels, max_texels: int) -> "TwigAtlas":
        """The levels' cards, each level at its texel size in metres (texels (L,)), the finest of them made
        coarser (to one common size) when the tiles would hold more than `max_texels` texels; shelf packing, tallest tiles first, into a power-of-two
        width about the square root of their area (at least the widest tile)."""
        levels = tuple(levels)
        texel = np.concatenate([np.full(len(cards), float(t)) for cards, t in zip(levels, texels)])
        if np.any(~(texel > 0)):
            raise TwigCardError(f"twig atlas texel sizes {list(texels)} are invalid: allowed numbers > 0 metres")
        extent = np.concatenate([cards.extent for cards in levels]) if levels else np.zeros((0, 2))
        if len(extent) == 0:
            return cls(levels, texel, np.zeros((0, 2), np.int64), (1, 1))
        texel = _coarsest_fitting(extent, texel, max_texels)
        tiles = np.ceil(extent / texel[:, None]).astype(np.int64) + 2 * TWIG_PADDING_TEXELS
        width = int(max(tiles[:, 0].max(), np.sqrt((tiles[:, 0] * tiles[:, 1]).sum() * 1.15)))
        width = 1 << int(np.ceil(np.log2(width)))
        order = np.lexsort((np.arange(len(tiles)), -tiles[:, 1]))
        offset = np.zeros((len(tiles), 2), np.int64)
        x = y = shelf = 0
        for card in order:  # one step per card (tens to hundreds), not per texel
            w, h = tiles[card]
            if x + w > width:
                x, y, shelf = 0, y + shelf, 0
            offset[card] = (x, y)
            x, shelf = x + w, max(shelf, h)
        return cls(levels, texel, offset, (width, int(y + shelf)))

    @cached_property
    def first(self) -> np.ndarray:
        """(L + 1,) int64, where each level's cards start in the atlas's numbering."""
        return np.concatenate([[0], np.cumsum([len(cards) for cards in self.levels])]).astype(np.int64)

    @cached_property
    def _cards(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """origin, axes and extent of every card in the atlas's numbering (see TwigCards)."""
        return tuple(np.concatenate([getattr(cards, name) for cards in self.levels])
                     for name in ("origin", "axes", "extent"))

    def to_atlas(self, points: np.ndarray, card: np.ndarray) -> np.ndarray:
        """(P, 3) float64 atlas-space points (column, row, depth; texels) of world points (P, 3) metres on cards
        (P,) int (atlas numbering): columns run along u, rows down the tile against v (image rows), depth along
        the normal away from TWIG_DEPTH_OFFSET."""
        origin, axes, extent = self._cards
        local = np.einsum("pj,pij->pi", np.asarray(points, np.float64) - origin[card], axes[card])
        local /= self.texel[card, None]
        column = self.offset[card, 0] + TWIG_PADDING_TEXELS + local[:, 0]
        row = self.offset[card, 1] + TWIG_PADDING_TEXELS + extent[card, 1] / self.texel[card] - local[:, 1]
        return np.stack([column - 0.5, row - 0.5, TWIG_DEPTH_OFFSET - local[:, 2]], axis=1)

    def from_atlas(self, edges: np.ndarray, card: np.ndarray) -> np.ndarray:
        """(P, 3) float64 world points (metres) on cards (P,) int (atlas numbering) of atlas texel-edge coordinates
        (P, 2) (column, row; texel (c, r) spans [c, c + 1] x [r, r + 1]): the inverse of `to_atlas` on the card."""
        origin, axes, extent = self._cards
        edges = np.asarray(edges, np.float64)
        texel = self.texel[card]
        u = (edges[:, 0] - self.offset[card, 0] - TWIG_PADDING_TEXELS) * texel
        v = (self.offset[card, 1] + TWIG_PADDING_TEXELS - edges[:, 1]) * texel + extent[card, 1]
        return origin[card] + u[:, None] * axes[card, 0] + v[:, None] * axes[card, 1]

    @cached_property
    def card_index(self) -> np.ndarray:
        """(H, W) int64 atlas image of the card each texel's tile belongs to (-1 between tiles)."""
        width, height = self.size
        index = np.full((height, width), -1, np.int64)
        extent = self._cards[2] if self.levels else np.zeros((0, 2))
        tiles = np.ceil(extent / self.texel[:, None]).astype(np.int64) + 2 * TWIG_PADDING_TEXELS
        for card, ((column, row), (w, h)) in enumerate(zip(self.offset, tiles)):  # per card, not per texel
            index[row:row + h, column:column + w] = card
        return index

    def atlas_tree(self, lod0: TreeMesh) -> TreeMesh:
        """LOD0's faces of every card placed in atlas space (`to_atlas`), bark and leaves apart, for rendering the
        atlas with an orthographic camera looking down +depth (pixel centres at integer column, row)."""
        parts = []
        for part, kind in ((lod0.bark, "bark"), (lod0.leaves, "leaf")):
            faces = np.concatenate([getattr(cards, f"{kind}_faces") for cards in self.levels])
            card = np.concatenate([getattr(cards, f"{kind}_card") + start
                                   for cards, start in zip(self.levels, self.first)])
            points = np.asarray(part.vertices, np.float64)[part.faces[faces]].reshape(-1, 3)
            placed = self.to_atlas(points, np.repeat(card, 3)).astype(np.float32)
            parts.append(MeshPart(placed, np.arange(len(placed), dtype=np.int32).reshape(-1, 3),
                                  np.tile(np.float32([0, 0, -1]), (len(placed), 1)),
                                  np.zeros((len(placed), 2), np.float32)))
        return TreeMesh(bark=parts[0], leaves=parts[1], bark_color=lod0.bark_color, leaf_color=lod0.leaf_color,
                        name=f"{lod0.name}_twig_atlas")

    def card_part(self, level: int) -> MeshPart:
        """The cards of `levels[level]` as a mesh: four corners and two triangles each, UVs into the atlas (OBJ
        convention, v = 0 at the bottom row), normals along each card's normal, and `branch` (V,) int32, the
        LOD0 branch each card grows from nearest the trunk."""
        cards = self.levels[level]
        corners = cards.corners.reshape(-1, 3)
        card = np.repeat(np.arange(len(cards)) + self.first[level], 4)
        placed = self.to_atlas(corners, card)[:, :2] + 0.5  # texel edges, not centres
        width, height = self.size
        uvs = np.stack([placed[:, 0] / width, 1.0 - placed[:, 1] / height], axis=1)
        return MeshPart(corners, quad_faces(len(cards)), np.repeat(cards.axes[:, 2], 4, axis=0), uvs,
                        {"branch": np.repeat(cards.branch, 4).astype(np.int32)})


def _coarsest_fitting(extent: np.ndarray, texel: np.ndarray, max_texels: int) -> np.ndarray:
    """(C,) float64 texels: max(texel, t) with the least t (bisection) whose tiles (extent (C, 2) metres, padded)
    hold at most `max_texels` texels, so fine levels give way before coarse ones do."""
    def texels(floor: float) -> float:
        size = extent / np.maximum(texel, floor)[:, None] + 2 * TWIG_PADDING_TEXELS
        return float(np.prod(size, axis=1).sum())

    if texels(0.0) <= max_texels:
        return texel
    low, high = float(texel.min()), float(texel.max())
    while texels(high) > max_texels:
        high *= 2.0
    for _ in range(40):
        mid = 0.5 * (low + high)
        low, high = (mid, high) if texels(mid) > max_texels else (low, mid)
    return np.maximum(texel, high)
