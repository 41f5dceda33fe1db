"""The asset as USD (`.usdc` via usd-core): Z up, metres, a `lod` variant set (LOD0.., IMPOSTOR) and a `season`
variant set (spring, summer, autumn, bare without leaves), leaves as a PointInstancer of a leaf card (and, on
coarser levels, a clump card; a `cutout` asset's leaf is its opaque outline polygon), wind primvars; an
octahedral impostor's layout in its prim's `treefarm:impostor` custom data.

In: a LibraryAsset and the texture file names beside it. Out: `.usdc` bytes (written through a temporary file).
"""
from __future__ import annotations

import os
import tempfile

import numpy as np

from species.geometry import unit_quaternions
from species.meshing.tubes_and_cards import CARD_FACES, CARD_UVS
from species.studio.lod import card_clumps
from species.studio.pbr_textures import SEASONS
from species.skeleton import LEAF_CARD_CORNERS
from species.tree_mesh import MeshPart

from .asset import LibraryAsset, leaf_instances
from .usd_wind import bind_skin, define_skeleton, joint_xforms, lean_whole, set_clip_time_range

__all__ = ["asset_to_usdc", "TEXTURE_FILES", "TWIG_TEXTURE_FILES", "prim_name"]

# Texture files written beside the USD (relative asset paths in the shaders).
TEXTURE_FILES = {"bark_base_color": "textures/bark_base_color.png", "bark_normal": "textures/bark_normal.png",
                 "bark_roughness_metallic": "textures/bark_roughness_metallic.png",
                 "impostor_albedo": "textures/impostor_albedo.png", "impostor_normal": "textures/impostor_normal.png",
                 **{f"leaf_atlas_{s}": f"textures/leaf_atlas_{s}.png" for s in SEASONS if s != "bare"}}
# And for an asset whose levels draw twig cards (`LibraryAsset.twig_atlas`): one albedo per season, bare included.
TWIG_TEXTURE_FILES = {"twig_normal": "textures/twig_normal.png",
                      **{f"twig_atlas_{s}": f"textures/twig_atlas_{s}.png" for s in SEASONS}}


def prim_name(asset_id: str) -> str:
    """A valid USD prim name for an asset id (letters, digits, '_'; not starting with a digit)."""
    cleaned = "".join(c if c.isalnum() else "_" for c in asset_id)
    return cleaned if not cleaned[0].isdigit() else f"_{cleaned}"


def _material(stage, path: str, colour_file: str | None, normal_file: str | None, roughness_file: str | None,
              opacity_from_texture: bool, roughness: float, wrap: str):
    """A UsdPreviewSurface material; `wrap` ("repeat" for tiling bark, "clamp" for atlases) as in the GLB's
    samplers, so an atlas tile's edge never samples its neighbour."""
    from pxr import Sdf, UsdShade

    material = UsdShade.Material.Define(stage, path)
    shader = UsdShade.Shader.Define(stage, f"{path}/surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.0)
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    reader = UsdShade.Shader.Define(stage, f"{path}/st")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
    st = reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)

    def texture(name: str, file: str, colour: bool):
        tex = UsdShade.Shader.Define(stage, f"{path}/{name}")
        tex.CreateIdAttr("UsdUVTexture")
        tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(file)
        tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(st)
        tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("sRGB" if colour else "raw")
        tex.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set(wrap)
        tex.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set(wrap)
        return tex

    if colour_file:
        tex = texture("base_color", colour_file, True)
        shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(
            tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3))
        if opacity_from_texture:
            shader.CreateInput("opacity", Sdf.ValueTypeNames.Float).ConnectToSource(
                tex.CreateOutput("a", Sdf.ValueTypeNames.Float))
            shader.CreateInput("opacityThreshold", Sdf.ValueTypeNames.Float).Set(0.5)
    if normal_file:
        tex = texture("normal", normal_file, False)
        tex.CreateInput("scale", Sdf.ValueTypeNames.Float4).Set((2.0, 2.0, 2.0, 1.0))
        tex.CreateInput("bias", Sdf.ValueTypeNames.Float4).Set((-1.0, -1.0, -1.0, 0.0))
        shader.CreateInput("normal", Sdf.ValueTypeNames.Normal3f).ConnectToSource(
            tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3))
    if roughness_file:
        tex = texture("roughness", roughness_file, False)
        shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).ConnectToSource(
            tex.CreateOutput("g", Sdf.ValueTypeNames.Float))
    else:
        shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(roughness)
    return material


def _mesh(stage, path: str, part, wind=None, pivot=None, uv_tile: int | None = None):
    from pxr import Sdf, UsdGeom, Vt

    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(part.vertices, np.float32)))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(part.n_faces, 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(part.faces.reshape(-1), np.int32)))
    mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(part.normals, np.float32)))
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    lo, hi = part.vertices.min(axis=0), part.vertices.max(axis=0)
    mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([lo, hi]).astype(np.float32)))
    primvars = UsdGeom.PrimvarsAPI(mesh)
    uvs = np.asarray(part.uvs, np.float32).copy()
    if uv_tile is not None:
        uvs[:, 0] = 0.5 * uvs[:, 0] + 0.5 * uv_tile
    primvars.CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex).Set(
        Vt.Vec2fArray.FromNumpy(uvs))
    if wind is not None:
        primvars.CreatePrimvar("wind", Sdf.ValueTypeNames.Float4Array, UsdGeom.Tokens.vertex).Set(
            Vt.Vec4fArray.FromNumpy(np.ascontiguousarray(wind, np.float32)))
        primvars.CreatePrimvar("windPivot", Sdf.ValueTypeNames.Float3Array, UsdGeom.Tokens.vertex).Set(
            Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(pivot, np.float32)))
    return mesh


# The PointInstancer's prototype of single-leaf cards and of clump cards (`card_clumps` False / True).
PROTOTYPE_NAMES = {False: "leaf", True: "clump"}


def _leaf_instancer(stage, path: str, level, card_material, chosen: np.ndarray | None = None,
                    origin: np.ndarray | None = None, leaves=None, cutout_material=None) -> list[str]:
    """The level's leaves as a PointInstancer at `path`; returns the names of the prototypes it made. Skeletal
    wind gives one per joint: the `chosen` (M,) bool leaves, placed from `origin` (3,), `leaves` the level's
    (translation, unit quaternion x y z w, scale, clump) per card, made once. A level with a `leaf_outline`
    draws its single leaves as that polygon, bound to `cutout_material` (opaque)."""
    from pxr import Sdf, UsdGeom, UsdShade, Vt

    instancer = UsdGeom.PointInstancer.Define(stage, path)
    card = MeshPart(LEAF_CARD_CORNERS, CARD_FACES, np.tile([0.0, 1.0, 0.0], (4, 1)), CARD_UVS)
    # One prototype per card kind present: `leaf` (single-leaf tile) for cards that are one leaf, `clump`
    # (clump tile) for cards that merge several.
    chosen = np.ones(level.skeleton.n_leaves, bool) if chosen is None else chosen
    if leaves is None:
        translation, rotation, scale = leaf_instances(level.skeleton)
        leaves = translation, unit_quaternions(rotation), scale, card_clumps(level.mesh.leaves)  # x, y, z, w
    translation, quat, scale, clumps = (array[chosen] for array in leaves)
    kinds = [kind for kind in (False, True) if (clumps == kind).any()]
    prototypes = []
    for kind in kinds:
        outline = level.leaf_outline if not kind else None
        shape = card if outline is None else MeshPart(outline.card_points, outline.faces,
                                                      np.tile([0.0, 1.0, 0.0], (len(outline.uvs), 1)), outline.uvs)
        prototype = _mesh(stage, f"{path}/prototypes/{PROTOTYPE_NAMES[kind]}", shape, uv_tile=int(kind))
        material = card_material if outline is None else cutout_material
        if material is not None:  # else the leaves' season binding above it holds
            UsdShade.MaterialBindingAPI.Apply(prototype.GetPrim()).Bind(material)
        prototypes.append(prototype.GetPath())
    instancer.CreatePrototypesRel().SetTargets(prototypes)
    if origin is not None:
        translation = translation - origin
    instancer.CreateProtoIndicesAttr(Vt.IntArray.FromNumpy(np.searchsorted(kinds, clumps).astype(np.int32)))
    instancer.CreatePositionsAttr(Vt.Vec3fArray.FromNumpy(translation.astype(np.float32)))
    # Vt reads each row as GfQuath lays it out: imaginary (x, y, z) first, then the real part w.
    instancer.CreateOrientationsAttr(Vt.QuathArray.FromNumpy(np.ascontiguousarray(quat, np.float16)))
    instancer.CreateScalesAttr(Vt.Vec3fArray.FromNumpy(scale.astype(np.float32)))
    primvars = UsdGeom.PrimvarsAPI(instancer)
    primvars.CreatePrimvar("wind", Sdf.ValueTypeNames.Float4Array, UsdGeom.Tokens.vertex).Set(
        Vt.Vec4fArray.FromNumpy(np.ascontiguousarray(level.leaf_wind[chosen], np.float32)))
    primvars.CreatePrimvar("windPivot", Sdf.ValueTypeNames.Float3Array, UsdGeom.Tokens.vertex).Set(
        Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(level.leaf_pivot[chosen], np.float32)))
    return [PROTOTYPE_NAMES[kind] for kind in kinds]


def _custom_data(values: dict) -> dict:
    """A JSON-able dict as USD custom data: lists of numbers as float or int arrays, the rest as it is."""
    from pxr import Vt

    out = {}
    for key, value in values.items():
        if isinstance(value, list) and all(isinstance(v, int) for v in value):
            value = Vt.IntArray(value)
        elif isinstance(value, list):
            value = Vt.DoubleArray(value)
        out[key] = value
    return out


def asset_to_usdc(asset: LibraryAsset) -> bytes:
    """`.usdc` bytes of the asset: /<id> (component, default prim) with Looks/, and Geom/ filled per `lod`
    variant (bark mesh + leaves PointInstancer, or the impostor card); the `season` variant set binds the leaf
    material of that season, and `bare` deactivates the leaves. Selected by default: LOD0, summer."""
    from pxr import Kind, Sdf, Usd, UsdGeom, UsdShade, UsdSkel, Vt

    layer = Sdf.Layer.CreateAnonymous(".usdc")
    stage = Usd.Stage.Open(layer)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, UsdGeom.LinearUnits.meters)
    root_path = f"/{prim_name(asset.asset_id)}"
    root = UsdGeom.Xform.Define(stage, root_path).GetPrim()
    stage.SetDefaultPrim(root)
    Usd.ModelAPI(root).SetKind(Kind.Tokens.component)
    root.SetCustomDataByKey("treefarm:asset_id", asset.asset_id)
    root.SetCustomDataByKey("treefarm:switch_px", Vt.IntArray([int(lv.switch_px) for lv in asset.levels]))
    looks = f"{root_path}/Looks"
    UsdGeom.Scope.Define(stage, looks)
    bark = _material(stage, f"{looks}/bark", TEXTURE_FILES["bark_base_color"], TEXTURE_FILES["bark_normal"],
                     TEXTURE_FILES["bark_roughness_metallic"], False, 0.9, "repeat")
    leaves = {s: _material(stage, f"{looks}/leaves_{s}", TEXTURE_FILES[f"leaf_atlas_{s}"], None, None, True, 0.7,
                           "clamp")
              for s in SEASONS if s != "bare"}
    # `cutout` leaves: the same atlas on opaque outline polygons (no opacity, so no alpha test).
    cutout = {s: _material(stage, f"{looks}/leaves_cutout_{s}", TEXTURE_FILES[f"leaf_atlas_{s}"], None, None, False,
                           0.7, "clamp")
              for s in SEASONS if s != "bare"} if asset.leaf_outline is not None else {}
    impostor = _material(stage, f"{looks}/impostor", TEXTURE_FILES["impostor_albedo"],
                         TEXTURE_FILES["impostor_normal"], None, True, 0.8, "clamp")
    twigs = {s: _material(stage, f"{looks}/twigs_{s}", TWIG_TEXTURE_FILES[f"twig_atlas_{s}"],
                          TWIG_TEXTURE_FILES["twig_normal"], None, True, 0.8, "clamp")
             for s in SEASONS} if asset.twig_atlas is not None else {}
    geom = f"{root_path}/Geom"
    skins = asset.level_skins
    if skins:  # skinned meshes live under a SkelRoot; the skeleton and the leaves' joints serve every level
        UsdSkel.Root.Define(stage, geom)
        skeleton = define_skeleton(stage, f"{geom}/Skel", asset.wind_rig, asset.wind_clip)
        set_clip_time_range(stage, asset.wind_clip)
        with_leaves = np.unique(np.concatenate([skin.leaf_joint for skin in skins if skin is not None]))
        UsdGeom.Xform.Define(stage, f"{geom}/leaves")
        joint_prims = joint_xforms(stage, f"{geom}/leaves", asset.wind_rig, asset.wind_clip, with_leaves)
    else:
        UsdGeom.Xform.Define(stage, geom)
    lod_set = root.GetVariantSets().AddVariantSet("lod")
    prototype_names: set[str] = set()  # the leaf prototypes of every level (under Geom/leaves) each season binds
    outlined: set[str] = set()  # with skeletal wind: every joint's outline polygon prototype (a `cutout` asset)
    for k, level in enumerate(asset.levels):
        lod_set.AddVariant(level.name)
        lod_set.SetVariantSelection(level.name)
        with lod_set.GetVariantEditContext():
            if level.name == "IMPOSTOR":
                card = _mesh(stage, f"{geom}/impostor", level.mesh.bark)
                UsdShade.MaterialBindingAPI.Apply(card.GetPrim()).Bind(impostor)
                layout = asset.impostor.layout()
                if layout:  # an octahedral impostor: how its frames lie in the atlas
                    card.GetPrim().SetCustomDataByKey("treefarm:impostor", _custom_data(layout))
                if skins:
                    lean_whole(card.GetPrim(), asset.wind_clip)
            else:
                mesh = _mesh(stage, f"{geom}/bark", level.mesh.bark, level.bark_wind, level.bark_pivot)
                UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(bark)
                if skins:
                    bind_skin(mesh, skeleton, skins[k].bark_joints, skins[k].bark_weights)
                if level.skeleton.n_leaves and skins:
                    leaf_joint = skins[k].leaf_joint
                    translation, rotation, scale = leaf_instances(level.skeleton)
                    per_level = (translation, unit_quaternions(rotation), scale, card_clumps(level.mesh.leaves))
                    for joint in np.unique(leaf_joint):
                        made = _leaf_instancer(stage, f"{joint_prims[joint]}/cards", level, None, leaf_joint == joint,
                                               asset.wind_rig.position[joint], per_level)
                        if level.leaf_outline is not None and PROTOTYPE_NAMES[False] in made:
                            outlined.add(f"{joint_prims[joint]}/cards/prototypes/{PROTOTYPE_NAMES[False]}")
                elif level.skeleton.n_leaves:
                    made = _leaf_instancer(stage, f"{geom}/leaves", level, leaves["summer"],
                                           cutout_material=cutout.get("summer"))
                    prototype_names.update(f"prototypes/{kind}" for kind in made)
                if level.twigs is not None:
                    cards = _mesh(stage, f"{geom}/twigs", level.twigs, level.twig_wind, level.twig_pivot)
                    UsdShade.MaterialBindingAPI.Apply(cards.GetPrim()).Bind(twigs["summer"])
                    if skins:
                        bind_skin(cards, skeleton, skins[k].twig_joints, skins[k].twig_weights)
            stage.GetPrimAtPath(geom).SetCustomDataByKey("treefarm:switch_px", int(level.switch_px))
    lod_set.SetVariantSelection("LOD0")
    season_set = root.GetVariantSets().AddVariantSet("season")
    for season in SEASONS:
        season_set.AddVariant(season)
        season_set.SetVariantSelection(season)
        with season_set.GetVariantEditContext():
            if twigs:  # the twig cards keep their twigs in every season; their leaves follow it
                UsdShade.MaterialBindingAPI.Apply(stage.OverridePrim(f"{geom}/twigs")).Bind(twigs[season])
            over = stage.OverridePrim(f"{geom}/leaves")
            if season == "bare":
                over.SetActive(False)
            elif skins:  # every joint's cards under Geom/leaves take the season's binding from it
                UsdShade.MaterialBindingAPI.Apply(over).Bind(leaves[season])
                for path in sorted(outlined):  # but the outline polygons, which are opaque
                    UsdShade.MaterialBindingAPI.Apply(stage.OverridePrim(path)).Bind(cutout[season])
            else:
                for name in sorted(prototype_names):
                    card = stage.OverridePrim(f"{geom}/leaves/{name}")
                    outlined = cutout and name == f"prototypes/{PROTOTYPE_NAMES[False]}"
                    UsdShade.MaterialBindingAPI.Apply(card).Bind(cutout[season] if outlined else leaves[season])
    season_set.SetVariantSelection("summer")
    # `season` first among the prim's variant sets: its leaf bindings are then stronger than the `lod` variants'.
    layer.GetPrimAtPath(root_path).variantSetNameList.prependedItems = ["season", "lod"]
    handle, path = tempfile.mkstemp(suffix=".usdc")
    os.close(handle)
    try:
        layer.Export(path)
        with open(path, "rb") as stream:
            return stream.read()
    finally:
        os.unlink(path)
