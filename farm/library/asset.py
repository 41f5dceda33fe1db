"""One library asset in memory: LOD0 and coarser levels, impostor, wind data, collision capsules, textures and the
measured quality of the chain (triangles, switch size and silhouette IoU per level).

In: species name, tree seed, LibrarySpec, the process's CoverageRenderer and a StageTimer. Out: `LibraryAsset`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

import species
from renderers.alpha_coverage import coverage_tree, opaque_fraction
from renderers.framing import framing_points
from renderers.impostor import render_impostors
from renderers.silhouette_metric import QUALITY_AZIMUTHS, closed_silhouette, silhouette_iou, switch_camera
from renderers.octahedral_impostor import render_octahedral_impostor
from species.meshing.tubes_and_cards import CARD_FACES
from species.studio.collision import collision_capsules
from species.studio.leaf_cutout import trace_leaf_outline
from species.studio.lod import card_clumps
from species.studio.pbr_textures import SEASONS, bark_maps, leaf_atlas, season_leaf_colour
from species.studio.skeletal_wind import wind_clip, wind_rig
from species.studio.wind import WIND_LAYOUT, wind_attributes

from ..tree_chain import stage_rngs
from .lod_fit import drawn_cover, fit_impostor, fit_lods, settle_twigs
from .skinned_levels import level_skins

__all__ = ["LibraryAsset", "LevelData", "asset_id", "build_asset", "build_asset_from_tree", "leaf_instances",
           "leaf_alphas", "leaf_fractions",
           "measure_chain"]


def asset_id(species_name: str, seed: int) -> str:
    """Stable id of an asset: its species and tree seed (the same spec and seed give the same id)."""
    return f"{species_name}-{int(seed):016x}"


@dataclass
class LevelData:
    """One level (0..3) of detail, or the impostor (level = len(lods) + 1 with name "IMPOSTOR").

    name     : "LOD0", "LOD1", ..., "IMPOSTOR".
    mesh     : TreeMesh (bark with `branch`, leaves = cards); impostor: bark = billboard, no leaves.
    skeleton : the skeleton meshed (None for the impostor).
    bark_wind, bark_pivot : (V, 4) / (V, 3) float32 wind attributes of the bark vertices (Z up).
    leaf_wind, leaf_pivot : (M, 4) / (M, 3) float32 wind attributes per leaf card (instance).
    switch_px : tree height on screen at which this level takes over (0 for LOD0).
    iou      : per-azimuth silhouette IoU against LOD0 at switch_px (empty for LOD0).
    twigs    : the level's twig cluster cards (`TwigAtlas.card_part`: UVs into the asset's twig atlas, `branch`),
               or None; twig_wind, twig_pivot: (4 C, 4) / (4 C, 3) float32 wind attributes of their vertices.
    """

    name: str
    mesh: object
    skeleton: object
    bark_wind: np.ndarray
    bark_pivot: np.ndarray
    leaf_wind: np.ndarray
    leaf_pivot: np.ndarray
    switch_px: int
    iou: list[float] = field(default_factory=list)
    twigs: object = None
    twig_index: int = -1  # the level's cards are `twig_atlas.layout.levels[twig_index]`
    twig_wind: np.ndarray | None = None
    twig_pivot: np.ndarray | None = None
    leaf_outline: object = None  # species.studio.leaf_cutout.LeafOutline: single leaves drawn as its polygon
    lod0_branch: np.ndarray | None = None  # (B',) int64 the LOD0 branch of each of the level's branches

    def lod0_branches(self, branch: np.ndarray) -> np.ndarray:
        """The LOD0 branch ids of this level's branch ids (an array of any shape)."""
        return np.asarray(branch, np.int64) if self.lod0_branch is None else self.lod0_branch[branch]

    @property
    def n_triangles(self) -> int:
        triangles = int(self.mesh.n_faces) + (self.twigs.n_faces if self.twigs is not None else 0)
        if self.leaf_outline is not None:  # each single-leaf card's two triangles become the outline's
            singles = int(np.count_nonzero(~card_clumps(self.mesh.leaves)))
            triangles += singles * (self.leaf_outline.n_triangles - len(CARD_FACES))
        return triangles


@dataclass
class LibraryAsset:
    """Everything one asset's files are written from."""

    asset_id: str
    species: str
    generator: str
    seed: int
    params: dict
    skeleton: object
    levels: list[LevelData]
    impostor: object  # renderers.impostor.ImpostorAtlas or renderers.octahedral_impostor.OctahedralAtlas
    capsules: np.ndarray
    bark_maps: object  # species.studio.pbr_textures.BarkMaps
    leaf_atlases: dict[str, np.ndarray]
    twig_atlas: object = None  # renderers.twig_atlas.TwigAtlasImage, when a level draws twig cards
    wind_rig: object = None  # species.studio.skeletal_wind.WindRig, when the spec asks for skeletal wind
    wind_clip: object = None  # its WindClip
    level_skins: list = field(default_factory=list)  # a skinned_levels.LevelSkin per level (None: impostor)
    leaf_outline: object = None  # the `cutout` leaves' LeafOutline (None: leaf cards)

    @property
    def lod0(self):
        return self.levels[0].mesh

    @cached_property
    def twig_albedos(self) -> dict[str, np.ndarray]:
        """(H, W, 4) uint8 twig atlas albedo per season (SEASONS order), made once for every file that embeds or
        writes them: the species' bark colour on bark texels and the season's leaf colour on leaf texels; `bare`
        keeps the twigs and cuts the leaves away. {} without twig cards."""
        if self.twig_atlas is None:
            return {}
        leaf = self.lod0.leaf_color
        albedos = {season: self.twig_atlas.albedo(self.lod0.bark_color,
                                                  None if season == "bare" else season_leaf_colour(season, leaf))
                   for season in SEASONS}
        for image in albedos.values():
            image.flags.writeable = False  # each file's writer encodes them: `PngCache` knows them by identity
        return albedos

    @cached_property
    def cutout_albedos(self) -> dict[str, np.ndarray]:
        """(h, 2 h, 3) uint8 leaf atlas colour without its alpha per leafy season, for `cutout` leaves' opaque
        material: with no alpha channel in the image, no importer (Blender's FBX one, Unity's) turns on an
        alpha test the outline polygons do not need. {} for leaf cards."""
        if self.leaf_outline is None:
            return {}
        albedos = {season: np.ascontiguousarray(atlas[..., :3]) for season, atlas in self.leaf_atlases.items()}
        for image in albedos.values():
            image.flags.writeable = False  # `PngCache` knows them by identity
        return albedos

    def metadata(self) -> dict:
        """JSON-able facts about the asset (catalog row without file entries)."""
        lod0_tris = self.levels[0].n_triangles
        return {
            "id": self.asset_id, "species": self.species, "generator": self.generator, "seed": int(self.seed),
            "params": self.params, "height_m": float(self.skeleton.height),
            "crown_radius_m": float(self.skeleton.crown_radius),
            "levels": [{"name": lv.name, "triangles": lv.n_triangles, "share_of_lod0": lv.n_triangles / lod0_tris,
                        "switch_px": lv.switch_px, **self._twig_facts(lv),
                        "iou_min": min(lv.iou) if lv.iou else 1.0,
                        "iou_mean": float(np.mean(lv.iou)) if lv.iou else 1.0,
                        "iou_per_azimuth": [round(v, 4) for v in lv.iou]} for lv in self.levels],
            "collision_capsules": [[round(float(v), 5) for v in row] for row in self.capsules],
            "wind_layout": WIND_LAYOUT,
            **({"skeletal_wind": self.skeletal_wind_facts()} if self.wind_rig is not None else {}),
        }

    def skeletal_wind_facts(self) -> dict:
        """What the baked wind clip is: its joints (names, parents, and how many per branch order), its length,
        keys and wind (docs/library.md, "Skeletal wind")."""
        rig, clip = self.wind_rig, self.wind_clip
        return {"joints": rig.n_joints, "joint_names": list(rig.names), "joint_parents": rig.parent.tolist(),
                "joints_per_order": np.bincount(rig.level).tolist(), "animation": "wind",
                "period_s": clip.duration, "keys": len(clip.times)}

    def _twig_facts(self, level) -> dict:
        """What a level's twig cards are: how many, and whether they carry their branches' leaves (False: bark
        cards, the leaves drawn as leaf cards); null without any."""
        if level.twigs is None:
            return {"twig_cards": 0, "twig_cards_carry_leaves": None}
        cards = self.twig_atlas.layout.levels[level.twig_index]
        return {"twig_cards": len(cards), "twig_cards_carry_leaves": bool(cards.leaves)}


def leaf_instances(skeleton) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Leaf card instances of a skeleton: translation (M, 3), rotation matrices (M, 3, 3) and scale (M, 3),
    float64, Z up, with transform = T R S exactly when the card axes are orthogonal (nearest rotation otherwise)."""
    linear = skeleton.leaves[:, :3, :3].astype(np.float64)
    # Cards are made as rotation x scale, so their columns are orthogonal and normalising them is the polar
    # factor; only cards whose columns are not (to float32 precision) go through the SVD.
    rotation = linear / np.maximum(np.linalg.norm(linear, axis=1, keepdims=True), 1e-30)
    skew = np.abs(np.einsum("mki,mkj->mij", rotation, rotation) - np.eye(3)).max(axis=(1, 2))
    oblique = skew > 1e-5
    if oblique.any():
        u, _, vt = np.linalg.svd(linear[oblique])
        rotation[oblique] = u @ vt
    flip = np.linalg.det(rotation) < 0
    rotation[flip] = rotation[flip] @ np.diag([1.0, -1.0, 1.0])  # the card is flat in y: flip its normal axis
    scale = np.einsum("mji,mji->mi", rotation, linear)  # diag(R^T M)
    return skeleton.leaves[:, :3, 3].astype(np.float64), rotation, scale


def _level_wind(skeleton, mesh, original_node: np.ndarray | None):
    keys = None if original_node is None else original_node[skeleton.branch_starts]
    bark_wind, bark_pivot = wind_attributes(skeleton, mesh.bark.vertices, mesh.bark.attributes["branch"], keys)
    if skeleton.n_leaves:
        leaf_branch = skeleton.branch_id[skeleton.leaf_node]
        leaf_wind, leaf_pivot = wind_attributes(skeleton, skeleton.leaves[:, :3, 3], leaf_branch, keys)
    else:
        leaf_wind, leaf_pivot = np.zeros((0, 4), np.float32), np.zeros((0, 3), np.float32)
    return bark_wind, bark_pivot, leaf_wind, leaf_pivot


def leaf_alphas(atlas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(h, h) bool opaque texels of a leaf atlas's two tiles: the single leaf (LOD0 cards) and the clump
    (cluster cards), at the alpha cutoff of the files' materials (0.5)."""
    tile = atlas.shape[0]
    opaque = atlas[..., 3] >= 128
    return opaque[:, :tile], opaque[:, tile:2 * tile]


def leaf_fractions(atlas: np.ndarray) -> tuple[float, float]:
    """Opaque shares of a leaf atlas's two tiles (single leaf, clump): how much of its card each leaf or
    cluster card covers, the rule `renderers.alpha_coverage` measures silhouettes by."""
    return tuple(opaque_fraction(alpha) for alpha in leaf_alphas(atlas))


def measure_chain(renderer, levels: list[LevelData], atlas, lod0_fraction: float, card_fraction: float,
                  lod0_cover=None, twig_atlas=None, points=None) -> None:
    """Fill each level's `iou`: silhouette IoU against LOD0 at the level's switch size from QUALITY_AZIMUTHS,
    both drawn through the same camera in one depth-only pass each, every leaf card shrunk to the opaque share
    of the tile it uses (`lod0_fraction` of the single leaf for LOD0's cards and for LOD cards that are one
    leaf; `card_fraction` of the clump for cards that merge several), the impostor as its atlas shows it
    (`atlas.coverage`); `points`: LOD0's `framing_points`, when the caller has them.
    Each LOD0 reference (azimuth, size) is rendered once."""
    lod0 = levels[0].mesh
    lod0_cover = lod0_cover or coverage_tree(lod0, lod0_fraction)
    points = framing_points(lod0) if points is None else points
    cameras = {(azimuth, level.switch_px): switch_camera(points, azimuth, level.switch_px)
               for level in levels[1:] for azimuth in QUALITY_AZIMUTHS}
    # LOD0 first for every camera, then each level: the renderer uploads each mesh once.
    references = {key: closed_silhouette(renderer.coverage(lod0_cover, camera)) for key, camera in cameras.items()}
    for level in levels[1:]:
        if level.name == "IMPOSTOR":
            draw = atlas.coverage  # the crossed planes cut by their alpha, or the octahedral frames the view blends
        else:
            runs = twig_atlas.opaque_runs(level.twig_index) if level.twigs is not None else None
            cover = drawn_cover(level.mesh, lod0_fraction, card_fraction, runs)
            draw = lambda camera: renderer.coverage(cover, camera)  # noqa: E731
        keys = [(azimuth, level.switch_px) for azimuth in QUALITY_AZIMUTHS]
        level.iou = [silhouette_iou(references[key], closed_silhouette(draw(cameras[key]))) for key in keys]


def build_asset(species_name: str, seed: int, spec, renderer, timer) -> LibraryAsset:
    """Grow, simplify, texture and measure one asset (no files written)."""
    sample_rng, _ = stage_rngs(seed)
    ident = asset_id(species_name, seed)
    with timer.stage("sample"):
        params = species.sample(species_name, sample_rng)
    with timer.stage("grow"):
        skeleton, lod0 = species.rebuild(params, name=ident)
    return build_asset_from_tree(ident, species_name, seed, params, skeleton, lod0, spec, renderer, timer)


def build_asset_from_tree(ident: str, species_name: str, seed: int, params: dict, skeleton, lod0, spec, renderer,
                          timer) -> LibraryAsset:
    """Simplify, texture and measure one asset from a grown tree (its skeleton and LOD0 mesh, e.g. a hand-modelled
    one); `species_name` picks the bark and leaf textures (no files written)."""
    with timer.stage("textures"):  # cached per species, colour and size: most assets hit the cache
        maps = bark_maps(species_name, lod0.bark_color, spec.texture_size)
        atlases = {season: leaf_atlas(season_leaf_colour(season, lod0.leaf_color), spec.texture_size // 2)
                   for season in SEASONS if season != "bare"}
        lod0_fraction, card_fraction = leaf_fractions(atlases["summer"])
    with timer.stage("lods"):
        lod0_cover = coverage_tree(lod0, lod0_fraction)  # LOD0's leaf cards cut to their texture's opaque share
        points = framing_points(lod0)  # every camera on LOD0 below is framed by these
        fitted = fit_lods(skeleton, lod0, lod0_cover, spec.lod_budgets, spec.switch_px, renderer, lod0_fraction,
                          card_fraction, points, twig_cards=spec.twig_cards)
    with timer.stage("twigs"):
        lods, twig_atlas, twig_slots = settle_twigs(fitted, skeleton, lod0_cover, renderer, lod0_fraction,
                                                    card_fraction)
    with timer.stage("wind"):
        levels = [LevelData("LOD0", lod0, skeleton, *_level_wind(skeleton, lod0, None), switch_px=0)]
        for k, (lod, px) in enumerate(zip(lods, spec.switch_px)):
            level = LevelData(f"LOD{lod.level}", lod.mesh, lod.skeleton,
                              *_level_wind(lod.skeleton, lod.mesh, lod.original_node), switch_px=int(px),
                              lod0_branch=skeleton.branch_id[lod.original_node[lod.skeleton.branch_starts]]
                              .astype(np.int64))
            if twig_slots[k] >= 0:
                level.twig_index = twig_slots[k]
                level.twigs = twig_atlas.layout.card_part(level.twig_index)
                # Each card sways with the LOD0 branch it grows from nearest the trunk.
                level.twig_wind, level.twig_pivot = wind_attributes(skeleton, level.twigs.vertices,
                                                                    level.twigs.attributes["branch"], None)
            levels.append(level)
        capsules = collision_capsules(skeleton)
        clip_settings = spec.wind_clip
        rig = wind_rig(skeleton, clip_settings.joint_budget) if clip_settings is not None else None
        clip = wind_clip(rig, clip_settings) if clip_settings is not None else None
    with timer.stage("impostor"):
        if spec.impostor == "octahedral":
            atlas = render_octahedral_impostor(renderer, lod0_cover, spec.impostor_frames, spec.impostor_tile)
        else:
            atlas = fit_impostor(lambda shares: render_impostors(renderer, lod0_cover, tile=spec.impostor_tile,
                                                                 axis_shares=shares),
                                 points, lod0_cover, renderer, spec.switch_px[-1])
        billboard = species.TreeMesh(bark=atlas.mesh(), leaves=species.MeshPart.empty(), name=f"{ident}_IMPOSTOR")
        empty4, empty3 = np.zeros((0, 4), np.float32), np.zeros((0, 3), np.float32)
        levels.append(LevelData("IMPOSTOR", billboard, None, np.zeros((billboard.bark.n_vertices, 4), np.float32),
                                np.zeros((billboard.bark.n_vertices, 3), np.float32), empty4, empty3,
                                switch_px=int(spec.switch_px[-1])))
    with timer.stage("quality"):
        measure_chain(renderer, levels, atlas, lod0_fraction, card_fraction, lod0_cover, twig_atlas, points)
    with timer.stage("wind"):
        skins = level_skins(rig, levels)
    outline = None
    if spec.leaves == "cutout":
        with timer.stage("cutout"):
            outline = trace_leaf_outline(leaf_alphas(atlases["summer"])[0])  # every season's leaf has one shape
            for level in levels[:-1]:
                level.leaf_outline = outline
    return LibraryAsset(ident, species_name, params.get("generator", "weber_penn"), int(seed), params, skeleton,
                        levels, atlas, capsules, maps, atlases, twig_atlas, rig, clip, skins, outline)
