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
from ..geometry.sectors import plane_sectors
from ..geometry.topology import depth_levels, node_depths
from ..geometry.vectors import dot3, row_bounds
from .leaf_clusters import cluster_axes

__all__ = ["TwigCards", "TwigAtlas", "TwigCardError", "twig_labels", "twig_cards", "TWIG_PADDING_TEXELS",
           "TWIG_DEPTH_OFFSET", "TWIG_CARD_PLANES", "TWIG_AXIS_SHARE", "TWIG_SECTOR_OVERLAP",
           "SHARED_TEXEL_RATIO", "UPRIGHT_PLANES", "LEVEL_SPRAY_NORMAL_Z", "BUDGETED_TEXELS_PER_PIXEL",
           "BUDGETED_MAX_PLANES"]

# Empty texels around each card's tile, so a sampled mip or a bilinear tap never reads its neighbour.
TWIG_PADDING_TEXELS = 2
# Atlas-space depth (texels) added so every flattened face lies in front of the atlas camera.
TWIG_DEPTH_OFFSET = 1.0e4
# Extra share of the card beyond its faces on each side (texel rounding is added on top).
_CARD_MARGIN = 0.02
# Cards per twig cluster, crossed on the cluster's principal axis. A single card shows its twigs exactly from the
# front and pressed to a line from the side; two crossed cards keep a bushy cluster's width from every side, for
# twice the triangles per cluster (docs/library.md, "Twig cluster cards", compares one and two).
TWIG_CARD_PLANES = 2
# At most this many planes per cluster (as many as the impostor has).
_MAX_PLANES = 8
# Clusters of this many planes or more (the far level's whole subtrees, seen from about level) cross on the
# vertical, as the impostor's planes do, not on their principal axis: a flat spray's planes lie along its own
# axes, so seen from the side one of them is edge-on and the other shows it pressed thin. From 3 planes, or at
# every level, upright loses more than it gains (tilted sprays, a sapling's 3-plane clusters; docs/library.md).
UPRIGHT_PLANES = 4
# A cluster of fewer planes crosses upright too when it lies about level (the z of its least-spread axis above
# this, its own plane within about 25 deg of level): crossed on its principal axis, its first plane would be all
# but edge-on from every side. A lower threshold (0.8 or 0.707) turns sprays that are not level and loses LOD2 or
# LOD3 on average over the presets.
LEVEL_SPRAY_NORMAL_Z = 0.9
# Crossed cards share faces as the impostor's planes do (renderers.impostor.AXIS_SHARE, SECTOR_OVERLAP): those
# within this share of the cluster's reach from its axis go on every plane (seen between the planes, the axis
# would otherwise come only from cards nearly edge-on), and those in this outer share of a sector on both planes
# beside it. Chosen on six presets' LOD1-LOD3 against 0 and 0.3 for both.
TWIG_AXIS_SHARE = 0.2
TWIG_SECTOR_OVERLAP = 0.15
# A card every level draws (a branch all of them drop, split alike) samples the nearest level's tile, unless that
# tile was asked more than this many times finer than its own level's texel: sampled four times finer, a far
# level's thin twigs fall between its pixel centres (a conifer's far level sampling its near level's tiles loses
# its twigs; sharing the rest frees budget for LOD2's own cards).
SHARED_TEXEL_RATIO = 2.0
# Cards of at most this many planes per cluster that carry their leaves (the nearer levels': LOD2 may take up to
# 4, `farm.library.lod_fit.MIDDLE_TWIG_PLANES`) share the atlas budget at BUDGETED_TEXELS_PER_PIXEL; the far
# level's up to 8 come on top at one texel a pixel. LOD2's 3-4 plane cards on top of the budget at one texel a
# pixel are too coarse, for no gain at LOD3 (docs/library.md).
BUDGETED_MAX_PLANES = 4
# Texels per screen pixel (at the level's switch size) asked of the cards the atlas budget holds: sampled twice,
# into texels and then into pixels, a twig thinner than a pixel breaks up; at two texels a pixel less of it does.
# The cards outside the budget (bark cards, the far level's many planes) keep one.
BUDGETED_TEXELS_PER_PIXEL = 2.0


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
    bark_faces, leaf_faces : (F,) int64 indices of LOD0's bark / leaf faces each card stands for (a face near
                             the axis of crossed cards is listed once per card it is drawn on), and
    bark_card, leaf_card   : (F,) int64 their card.
    planes         : cards per cluster asked for (1..8; a plane left empty is dropped).
    leaves         : whether the cards carry their branches' leaves; False for bark cards (no leaf faces: the
                     level draws those leaves as leaf cards).
    """

    origin: np.ndarray
    axes: np.ndarray
    extent: np.ndarray
    branch: np.ndarray
    bark_faces: np.ndarray
    bark_card: np.ndarray
    leaf_faces: np.ndarray
    leaf_card: np.ndarray
    planes: int = TWIG_CARD_PLANES
    leaves: bool = True

    def __len__(self) -> int:
        return len(self.origin)

    @property
    def budgeted(self) -> bool:
        """Whether the atlas budget holds these cards' tiles: cards carrying their leaves, at most
        BUDGETED_MAX_PLANES per cluster. Bark cards (a near level's every dropped branch, thin strips) and a far
        level's many planes come on top of it, so they do not coarsen the others."""
        return self.leaves and self.planes <= BUDGETED_MAX_PLANES

    def asked_texel(self, metres_per_px: float) -> float:
        """Metres per texel these cards ask at a switch size of `metres_per_px` metres per screen pixel."""
        return metres_per_px / BUDGETED_TEXELS_PER_PIXEL if self.budgeted else metres_per_px

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
            corners = part.face_corners[faces]  # (F, 3, 3): per face, so each card's values are gathered once
            normal = self.axes[card, 2]
            offset = dot3(corners - self.origin[card][:, None, :], normal[:, None, :])
            flat = (corners - offset[..., None] * normal[:, None, :]).astype(np.float32).reshape(-1, 3)
            parts.append(MeshPart(flat, np.arange(len(flat), dtype=np.int32).reshape(-1, 3),
                                  np.repeat(normal.astype(np.float32), 3, axis=0), np.zeros((len(flat), 2), np.float32)))
        return TreeMesh(bark=parts[0], leaves=parts[1], bark_color=lod0.bark_color, leaf_color=lod0.leaf_color,
                        name=f"{lod0.name}_twigs")


def twig_cards(skeleton: Skeleton, lod0: TreeMesh, labels: np.ndarray, planes: int = TWIG_CARD_PLANES,
               leaves: bool = True) -> TwigCards:
    """Cards for branch labels of `twig_labels`, `planes` per label (1 to 8), crossed on the principal axis
    of its LOD0 faces (bark vertices of its branches, corners of their leaf cards; without `leaves`, bark cards:
    the bark alone, its leaves left to the level's leaf cards): the first in the plane of
    their two widest spreads, the others turned about that axis by 180 / planes degrees each. UPRIGHT_PLANES
    or more (a far level's whole subtrees), or a cluster lying about level (LEVEL_SPRAY_NORMAL_Z), cross on the
    vertical through the faces' mean instead, as the impostor's planes do, the first along their widest
    horizontal spread. Each face goes to the plane it lies nearest (`plane_sectors`), faces near a sector's edge
    or near the axis to more than one (TWIG_SECTOR_OVERLAP, TWIG_AXIS_SHARE); each card spans its faces, plus a
    small margin. A card seen edge-on shows its faces pressed flat: with two planes, a bushy subtree keeps its
    width from every side (TWIG_CARD_PLANES). Cards are numbered label by label, plane by plane; a plane no face
    lies nearest has none."""
    if isinstance(planes, bool) or not isinstance(planes, (int, np.integer)) or not 1 <= planes <= _MAX_PLANES:
        raise TwigCardError(f"twig card planes {planes!r} are invalid: allowed an integer in [1, {_MAX_PLANES}]")
    labels = np.asarray(labels, np.int64)
    n = int(labels.max(initial=-1)) + 1
    # Labels per vertex (a face's vertices share its branch): the spreads are taken over vertices, not face corners.
    bark_vertex_label = labels[np.asarray(lod0.bark.attributes["branch"], np.int64)]
    leaf_vertex_label = labels[skeleton.branch_id[np.asarray(lod0.leaves.attributes["node"], np.int64)]] \
        if lod0.leaves.n_vertices and leaves else np.full(lod0.leaves.n_vertices, -1, np.int64)
    bark_label, leaf_label = bark_vertex_label[lod0.bark.faces[:, 0]], leaf_vertex_label[lod0.leaves.faces[:, 0]]
    bark_faces, leaf_faces = np.flatnonzero(bark_label >= 0), np.flatnonzero(leaf_label >= 0)
    face_label = [bark_label[bark_faces], leaf_label[leaf_faces]]
    vertex_label = np.concatenate([bark_vertex_label, leaf_vertex_label])
    on_card = vertex_label >= 0
    if n and np.bincount(vertex_label[on_card], minlength=n).min() == 0:
        raise TwigCardError("a twig card has no LOD0 faces: its branches drew nothing")
    vertices = np.concatenate([lod0.bark.vertices, lod0.leaves.vertices]).astype(np.float64)
    mean, axes = cluster_axes(vertices[on_card], vertex_label[on_card], n)
    # Rows: u along the principal axis, v along the second, normal along the least spread; right-handed. Plane p
    # turns v and the normal about u by p * 180 / planes degrees.
    u, v = axes[:, :, 2], axes[:, :, 1]
    # Upright (u vertical, v along the widest horizontal spread): every cluster of UPRIGHT_PLANES or more, and a
    # cluster lying about level (its least spread within LEVEL_SPRAY_NORMAL_Z of vertical).
    upright = (planes >= UPRIGHT_PLANES) | (np.abs(axes[:, 2, 0]) > LEVEL_SPRAY_NORMAL_Z)
    if upright.any():
        u = np.where(upright[:, None], [0.0, 0.0, 1.0], u)
        v = np.where(upright[:, None], _widest_horizontal(vertices[on_card], vertex_label[on_card], n), v)
    normal = np.cross(u, v)
    turn = np.radians(np.arange(planes) * (180.0 / planes))
    turned_v = np.cos(turn)[None, :, None] * v[:, None] + np.sin(turn)[None, :, None] * normal[:, None]
    frame = np.stack([np.broadcast_to(u[:, None], turned_v.shape), turned_v,
                      np.cross(u[:, None], turned_v)], axis=2).reshape(n * planes, 3, 3)
    faces, cards = [], []
    for part, face, label in zip((lod0.bark, lod0.leaves), (bark_faces, leaf_faces), face_label):
        rel = part.face_centroids[face] - mean[label]
        across, out = dot3(rel, v[label]), dot3(rel, normal[label])
        sector, neighbour, shared = plane_sectors(np.degrees(np.arctan2(out, across)), planes, TWIG_SECTOR_OVERLAP)
        radius = np.hypot(across, out)
        reach = np.zeros(n)
        np.maximum.at(reach, label, radius)
        axis = radius <= TWIG_AXIS_SHARE * reach[label]
        on_plane = [axis | (sector == p) | (shared & (neighbour == p)) for p in range(planes)]
        faces.append(np.concatenate([face[chosen] for chosen in on_plane]))
        cards.append(np.concatenate([label[chosen] * planes + p for p, chosen in enumerate(on_plane)]))
    # A plane no face lies nearest (a flat cluster, a lone leaf) gets no card: the others are renumbered.
    drawn = np.bincount(np.concatenate(cards), minlength=n * planes) > 0
    renumber = np.cumsum(drawn) - 1
    cards = [renumber[card] for card in cards]
    frame, card_mean = frame[drawn], np.repeat(mean, planes, axis=0)[drawn]
    # Each face's corners in its card's frame, reduced per face before per card (a third of the scattered values).
    face_card = np.concatenate(cards)
    rel = np.concatenate([part.face_corners[face] for part, face in zip((lod0.bark, lod0.leaves), faces)]) \
        - card_mean[face_card][:, None, :]
    low, high = np.full((2, len(frame)), np.inf), np.full((2, len(frame)), -np.inf)
    for k in range(2):  # one axis at a time: 1-D ufunc.at is many times faster than 2-D
        face_low, face_high = row_bounds(dot3(rel, frame[face_card, k][:, None, :]))
        np.minimum.at(low[k], face_card, face_low)
        np.maximum.at(high[k], face_card, face_high)
    low, high = low.T, high.T
    pad = _CARD_MARGIN * np.maximum(high - low, 1e-6)
    low, high = low - pad, high + pad
    origin = card_mean + np.einsum("ck,cki->ci", low, frame[:, :2])
    branch = np.full(n, np.iinfo(np.int64).max)
    np.minimum.at(branch, labels[labels >= 0], np.flatnonzero(labels >= 0))
    return TwigCards(origin, frame, high - low, np.repeat(branch, planes)[drawn], faces[0], cards[0], faces[1],
                     cards[1], int(planes), bool(leaves))


def _widest_horizontal(points: np.ndarray, labels: np.ndarray, n: int) -> np.ndarray:
    """(n, 3) float64 unit horizontal vectors: each cluster's direction of widest spread in plan view (points
    (P, 3) metres labelled (P,) int in [0, n)); +x where a cluster has no horizontal spread."""
    plan = np.asarray(points, np.float64).copy()
    plan[:, 2] = 0.0
    widest = cluster_axes(plan, labels, n)[1][:, :, 2]
    widest[:, 2] = 0.0
    length = np.linalg.norm(widest, axis=1, keepdims=True)
    return np.where(length > 1e-9, widest / np.maximum(length, 1e-12), [1.0, 0.0, 0.0])


@dataclass(frozen=True, eq=False)
class TwigAtlas:
    """Where each card of several levels lies in one atlas image, and the atlas-space geometry to render it from.

    levels : the TwigCards of each level, their cards numbered on end to end (card c of level k is
             `first[k] + c`).
    texel  : (C,) float64 metres per texel of each card.
    offset : (C, 2) int64 (column, row) of each tile's top-left texel; tiles are TWIG_PADDING_TEXELS larger than
             their card on every side.
    size   : (width, height) texels of the atlas.
    source : (C,) int64, the card whose tile each card samples: itself, or a card of a nearer level that is the
             same card (same frame, extent and LOD0 faces: a branch every level drops draws the same cards at
             each; `_tile_sources`), whose tile, texel and offset it shares.
    """

    levels: tuple
    texel: np.ndarray
    offset: np.ndarray
    size: tuple[int, int]
    source: np.ndarray

    @classmethod
    def pack(cls, levels, texels, max_texels: int) -> "TwigAtlas":
        """The levels' cards, each level at its texel size in metres (texels (L,)), made coarser when the tiles
        would hold more than `max_texels` texels (`_texels_within`: each level in proportion to the cube root of
        its texel times its cards' area, never finer than asked); shelf packing,
        tallest tiles first, into a power-of-two width about the square root of their area (at least the widest
        tile). A card that is the same as one of a nearer level (`_tile_sources`) gets no tile of its own: it
        samples that card's, at its finer texel, and takes nothing of the budget. A level whose cards are not
        `TwigCards.budgeted` (bark cards; more than BUDGETED_MAX_PLANES planes per cluster, the far level's) keeps
        its texel size and its tiles come on top of `max_texels`: they do not coarsen the other levels' cards."""
        levels = tuple(levels)
        texel = np.concatenate([np.full(len(cards), float(t)) for cards, t in zip(levels, texels)])
        if np.any(~(texel > 0)):
            raise TwigCardError(f"twig atlas texel sizes {list(texels)} are invalid: allowed numbers > 0 metres")
        extent = np.concatenate([cards.extent for cards in levels]) if levels else np.zeros((0, 2))
        if len(extent) == 0:
            return cls(levels, texel, np.zeros((0, 2), np.int64), (1, 1), np.zeros(0, np.int64))
        source = _tile_sources(levels, texels)
        own = source == np.arange(len(source))
        budgeted = own & np.concatenate([np.full(len(cards), cards.budgeted) for cards in levels])
        level = np.concatenate([np.full(len(cards), k) for k, cards in enumerate(levels)])
        texel[budgeted] = _texels_within(extent[budgeted], texel[budgeted], level[budgeted], max_texels)
        texel = texel[source]
        tiles = np.ceil(extent / texel[:, None]).astype(np.int64) + 2 * TWIG_PADDING_TEXELS
        width = int(max(tiles[own, 0].max(), np.sqrt((tiles[own, 0] * tiles[own, 1]).sum() * 1.15)))
        width = 1 << int(np.ceil(np.log2(width)))
        order = np.lexsort((np.arange(len(tiles)), -tiles[:, 1]))
        offset = np.zeros((len(tiles), 2), np.int64)
        x = y = shelf = 0
        for card in order[own[order]]:  # one step per tile (tens to hundreds), not per texel
            w, h = tiles[card]
            if x + w > width:
                x, y, shelf = 0, y + shelf, 0
            offset[card] = (x, y)
            x, shelf = x + w, max(shelf, h)
        return cls(levels, texel, offset[source], (width, int(y + shelf)), source)

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
        local = dot3((np.asarray(points, np.float64) - origin[card])[:, None, :], axes[card])
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
    def own_tile(self) -> np.ndarray:
        """(C,) bool: the cards with a tile of their own (`source` is themselves)."""
        return self.source == np.arange(len(self.source))

    @cached_property
    def card_index(self) -> np.ndarray:
        """(H, W) int64 atlas image of the card each texel's tile belongs to (its `source`; -1 between tiles)."""
        width, height = self.size
        index = np.full((height, width), -1, np.int64)
        extent = self._cards[2] if self.levels else np.zeros((0, 2))
        tiles = np.ceil(extent / self.texel[:, None]).astype(np.int64) + 2 * TWIG_PADDING_TEXELS
        for card in np.flatnonzero(self.own_tile):  # per tile, not per texel
            (column, row), (w, h) = self.offset[card], tiles[card]
            index[row:row + h, column:column + w] = card
        return index

    def atlas_tree(self, lod0: TreeMesh) -> TreeMesh:
        """LOD0's faces of every tile's card placed in atlas space (`to_atlas`), bark and leaves apart, for rendering
        the atlas with an orthographic camera looking down +depth (pixel centres at integer column, row)."""
        parts = []
        for part, kind in ((lod0.bark, "bark"), (lod0.leaves, "leaf")):
            faces = np.concatenate([getattr(cards, f"{kind}_faces") for cards in self.levels])
            card = np.concatenate([getattr(cards, f"{kind}_card") + start
                                   for cards, start in zip(self.levels, self.first)])
            drawn = self.own_tile[card]  # a shared tile is drawn once, from its own card
            faces, card = faces[drawn], card[drawn]
            points = part.face_corners[faces].reshape(-1, 3)
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


def _tile_sources(levels, texels) -> np.ndarray:
    """(C,) int64 per card of `levels` (numbered on end to end, asked texels (L,) metres): the card whose tile
    it samples. That is the first card with the same origin, axes and extent (bit for bit) and the same LOD0
    faces, unless that tile's level asked for texels more than SHARED_TEXEL_RATIO times finer; then the card
    has a tile of its own, which farther copies may share in turn. Itself where none comes before it."""
    frames = np.concatenate([np.concatenate([cards.origin, cards.axes.reshape(-1, 9), cards.extent], axis=1)
                             for cards in levels])
    rows = np.ascontiguousarray(frames).view(np.dtype((np.void, frames.itemsize * frames.shape[1]))).ravel()
    _, first, inverse = np.unique(rows, return_index=True, return_inverse=True)
    source = first[inverse.ravel()].astype(np.int64)
    copies = np.flatnonzero(source != np.arange(len(source)))
    if len(copies) == 0:
        return source
    # The same frame is the same faces in practice; checked all the same, face lists sorted per card once.
    starts = np.concatenate([[0], np.cumsum([len(cards) for cards in levels])])
    level = np.searchsorted(starts, np.arange(len(source)), side="right") - 1
    asked = np.asarray(texels, np.float64)
    listed = []
    for cards in levels:
        lists = []
        for faces, card in ((cards.bark_faces, cards.bark_card), (cards.leaf_faces, cards.leaf_card)):
            order = np.lexsort((faces, card))
            bounds = np.searchsorted(card[order], np.arange(len(cards) + 1))
            lists.append((faces[order], bounds))
        listed.append(lists)

    def faces_of(card: int):
        k, local = level[card], card - starts[level[card]]
        return [faces[bounds[local]:bounds[local + 1]] for faces, bounds in listed[k]]

    latest: dict[int, int] = {}  # first copy -> the tile its farther copies sample now
    for card in copies:  # per repeated card (tens to hundreds), nearest levels first
        first = int(source[card])
        if not all(np.array_equal(a, b) for a, b in zip(faces_of(card), faces_of(first))):
            source[card] = card
            continue
        tile = latest.get(first, first)
        if SHARED_TEXEL_RATIO * asked[level[tile]] < asked[level[card]]:
            source[card] = latest[first] = card
        else:
            source[card] = tile
    return source


def _texels_within(extent: np.ndarray, texel: np.ndarray, level: np.ndarray, max_texels: int) -> np.ndarray:
    """(C,) float64 texels (metres) of cards (extent (C, 2) metres, asked `texel` (C,), `level` (C,) int) whose
    padded tiles hold at most `max_texels` texels: as asked where they fit; else level k's texel is
    max(asked_k, s (asked_k area_k)^(1/3)), area_k its cards' area, with the least s (bisection) that fits.
    That split least raises the sum over levels of texels per screen pixel (t_k / asked_k, under
    sum area_k / t_k^2 fixed): a near level gives way less than one common size would make it, a far one more
    (docs/library.md)."""
    area = np.bincount(level, weights=extent[:, 0] * extent[:, 1])
    shape = np.cbrt(texel * area[level])

    def texels(scale: float) -> float:
        size = extent / np.maximum(texel, scale * shape)[:, None] + 2 * TWIG_PADDING_TEXELS
        return float(np.prod(size, axis=1).sum())

    if texels(0.0) <= max_texels:
        return texel
    low, high = 0.0, float((texel / shape).max())
    while texels(high) > max_texels:
        high *= 2.0
    for _ in range(50):
        mid = 0.5 * (low + high)
        low, high = (mid, high) if texels(mid) > max_texels else (low, mid)
    return np.maximum(texel, high * shape)
