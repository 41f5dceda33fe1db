"""The asset GLB: every level of detail and the impostor as named nodes (MSFT_lod on the root, screen coverages
in its extras), leaves as instanced cards (EXT_mesh_gpu_instancing: one card for single leaves, one for
clumps: meshes `<level>_leaf_card`, `<level>_clump_card`), seasons as KHR_materials_variants, wind attributes
`_WIND`/`_WIND_PIVOT`, PBR bark and a leaf atlas with alpha (a `cutout` asset: single leaves as opaque outline
polygons, `species.studio.leaf_cutout`); the normal-mapped primitives (bark, impostor) carry
TANGENT. An octahedral impostor's layout is in its level node's `extras.impostor`.

In: a LibraryAsset and the worker's PngCache. Out: GLB bytes (Y up, metres); same asset, same bytes.
`instanced=False` bakes the leaves into plain triangles (to measure what instancing saves). The GLB itself is
written by `species.meshing.gltf.GlbWriter`; this module lays out the library's scene.
"""
from __future__ import annotations

import numpy as np

from species.geometry import unit_quaternions, vertex_tangents
from species.meshing.gltf import CLAMP_TO_EDGE, REPEAT, TRIANGLES, Z_UP_TO_Y_UP, GlbWriter, z_up_to_y_up
from species.meshing.tubes_and_cards import CARD_FACES, CARD_UVS
from species.studio.pbr_textures import SEASONS
from species.studio.leaf_cutout import outline_leaves
from species.studio.lod import card_clumps
from species.tree_mesh import MeshPart
from species.skeleton import LEAF_CARD_CORNERS

from .asset import LibraryAsset, leaf_instances
from .gltf_wind import add_skin_attributes, joint_nodes, skin_entry, wind_animation
from .png_cache import PngCache

__all__ = ["asset_to_glb", "glb_size", "SCREEN_HEIGHT_PX", "EXTENSIONS", "CARD_MESH_KINDS"]

# MSFT_screencoverage values are switch sizes over this screen height (renderers.silhouette_metric's reference screen).
SCREEN_HEIGHT_PX = 1080
EXTENSIONS = ["EXT_mesh_gpu_instancing", "KHR_materials_variants", "MSFT_lod"]
# Instanced card meshes, `<level>_<kind>_card`, named as the USD's PointInstancer prototypes (`leaf`, `clump`).
CARD_MESH_KINDS = {"leaves": "leaf", "clumps": "clump"}


def _primitive(writer: GlbWriter, vertices, normals, uvs, faces, material: int, extra: dict | None = None,
               variants: list[dict] | None = None, tangents: np.ndarray | None = None) -> dict:
    """A triangle primitive (see `GlbWriter.triangles`), its season variants' material mappings in
    KHR_materials_variants. A primitive drawn with a normal map (in `material` or a variant's) gets TANGENT:
    `tangents` (V, 4) of these arrays (a MeshPart's cached `tangents`), or worked out here."""
    mapped = [material] + [mapping["material"] for mapping in variants or []]
    if any("normalTexture" in writer.materials[m] for m in mapped):
        # Left to the viewer, tangents differ between implementations (the validator's
        # MESH_PRIMITIVE_GENERATED_TANGENT_SPACE); the writer turns only POSITION and NORMAL to Y up.
        if tangents is None:
            tangents = vertex_tangents(vertices, normals, uvs, faces)
        extra = {"TANGENT": (np.concatenate([z_up_to_y_up(tangents[:, :3]), tangents[:, 3:]], axis=1), "VEC4"),
                 **(extra or {})}
    attributes, indices = writer.triangles(vertices, normals, uvs, faces, extra)
    entry = {"attributes": attributes, "material": material, "mode": TRIANGLES, "indices": indices}
    if variants:
        entry["extensions"] = {"KHR_materials_variants": {"mappings": variants}}
    return entry


def _materials(writer: GlbWriter, asset: LibraryAsset, pngs: PngCache) -> dict[str, int]:
    def texture(name: str, image: np.ndarray, wrap: int, palette: bool = False) -> dict:
        return {"index": writer.texture(name, pngs.encode(image, palette), wrap)}

    maps = asset.bark_maps
    bark = writer.material({"name": "bark", "pbrMetallicRoughness": {
        "baseColorTexture": texture("bark_base_color", maps.base_color, REPEAT),
        "metallicRoughnessTexture": texture("bark_roughness_metallic", maps.roughness_metallic, REPEAT),
        "metallicFactor": 1.0, "roughnessFactor": 1.0},
        "normalTexture": texture("bark_normal", maps.normal, REPEAT)})
    out = {"bark": bark}
    for season in SEASONS:
        entry = {"name": f"leaves_{season}", "alphaMode": "MASK", "alphaCutoff": 0.5, "doubleSided": True}
        if season == "bare":  # no leaves: everything cut away
            entry["pbrMetallicRoughness"] = {"baseColorFactor": [1.0, 1.0, 1.0, 0.0], "metallicFactor": 0.0}
        else:
            entry["pbrMetallicRoughness"] = {
                "baseColorTexture": texture(f"leaf_atlas_{season}", asset.leaf_atlases[season], CLAMP_TO_EDGE),
                "metallicFactor": 0.0, "roughnessFactor": 0.7}
        out[season] = writer.material(entry)
    if asset.leaf_outline is not None:
        # Outline polygons of single leaves: the atlas's colour without alpha, opaque (no alpha test); bare still
        # draws nothing.
        for season, image in asset.cutout_albedos.items():
            out[f"cutout_{season}"] = writer.material({
                "name": f"leaf_cutout_{season}", "doubleSided": True, "pbrMetallicRoughness": {
                    "baseColorTexture": texture(f"leaf_cutout_{season}", image, CLAMP_TO_EDGE),
                    "metallicFactor": 0.0, "roughnessFactor": 0.7}})
        out["cutout_bare"] = out["bare"]
    if asset.twig_atlas is not None:
        # Twig cluster cards: one atlas of bark and leaf texels, recoloured per season (bare keeps the twigs).
        normal = texture("twig_normal", asset.twig_atlas.normal, CLAMP_TO_EDGE)
        for season, image in asset.twig_albedos.items():
            out[f"twigs_{season}"] = writer.material({
                "name": f"twigs_{season}", "alphaMode": "MASK", "alphaCutoff": 0.5, "doubleSided": True,
                "pbrMetallicRoughness": {
                    "baseColorTexture": texture(f"twig_atlas_{season}", image, CLAMP_TO_EDGE, palette=True),
                    "metallicFactor": 0.0, "roughnessFactor": 0.8},
                "normalTexture": normal})
    atlas = asset.impostor
    out["impostor"] = writer.material({
        "name": "impostor", "alphaMode": "MASK", "alphaCutoff": 0.5, "doubleSided": True,
        "pbrMetallicRoughness": {"baseColorTexture": texture("impostor_albedo", atlas.albedo, CLAMP_TO_EDGE),
                                 "metallicFactor": 0.0, "roughnessFactor": 0.8},
        "normalTexture": texture("impostor_normal", atlas.normal, CLAMP_TO_EDGE)})
    return out


def _leaf_tile_uvs(uvs: np.ndarray, clump: np.ndarray) -> np.ndarray:
    """Card UVs (V, 2) into the atlas: the left tile (one leaf) where `clump` (V,) bool is False, the right (a
    clump of leaves) where it is True."""
    out = np.asarray(uvs, np.float64).copy()
    out[:, 0] = 0.5 * out[:, 0] + 0.5 * np.asarray(clump, np.float64)
    return out


def asset_to_glb(asset: LibraryAsset, instanced: bool = True, *, pngs: PngCache | None = None) -> bytes:
    """GLB bytes of the asset (see the module docstring). Scene: the LOD0 node; LOD1.. and IMPOSTOR are nodes
    outside the scene, listed by the root's MSFT_lod in order of decreasing detail. `pngs` encodes the textures
    (the worker's cache; None: a cache for this call)."""
    writer, head = _document(asset, instanced, pngs, keep_bytes=True)
    return writer.to_glb(head)


def glb_size(asset: LibraryAsset, instanced: bool = True, *, pngs: PngCache | None = None) -> int:
    """len(asset_to_glb(asset, instanced)), exactly, without packing the binary chunk (the same JSON is
    built; buffer views are counted, not copied): what the catalog reports for the file without instancing."""
    writer, head = _document(asset, instanced, pngs, keep_bytes=False)
    return writer.glb_length(head)


def _document(asset: LibraryAsset, instanced: bool, pngs: PngCache | None,
              keep_bytes: bool) -> tuple[GlbWriter, dict]:
    """The writer holding the asset's nodes, meshes, materials and binary chunk, and the document's head."""
    writer = GlbWriter(keep_bytes)
    materials = _materials(writer, asset, PngCache() if pngs is None else pngs)
    variant_maps = [{"material": materials[season], "variants": [i]} for i, season in enumerate(SEASONS)]
    skins = asset.level_skins
    level_nodes, level_joints, skin_entries, lean_node = [], [], [], None
    for k, level in enumerate(asset.levels):
        children = []
        mesh = level.mesh
        node = {"name": f"{asset.asset_id}_{level.name}"}
        if level.name == "IMPOSTOR":
            part = mesh.bark
            prim = _primitive(writer, part.vertices, part.normals, part.uvs, part.faces, materials["impostor"],
                              tangents=part.tangents)
            children.append(writer.node({"name": f"{asset.asset_id}_IMPOSTOR_card", "mesh": writer.mesh("impostor", prim)}))
            if skins:  # the card leans whole about the tree's base, turned by a node of its own
                lean_node = writer.node({"name": f"{asset.asset_id}_IMPOSTOR_lean", "children": children})
                children = [lean_node]
        else:
            bark = mesh.bark
            prim = _primitive(writer, bark.vertices, bark.normals, bark.uvs, bark.faces, materials["bark"],
                              {"_WIND": (level.bark_wind, "VEC4"),
                               "_WIND_PIVOT": (z_up_to_y_up(level.bark_pivot), "VEC3")}, tangents=bark.tangents)
            if skins:
                children, joints = _skinned_level(writer, asset, level, skins[k], prim, materials, variant_maps,
                                                  instanced, node)
                level_joints.append(joints)
                skin_entries.append(skin_entry(writer, asset.wind_rig, joints, f"{asset.asset_id}_{level.name}_wind"))
                node["skin"] = len(skin_entries) - 1
            else:
                children.append(writer.node({"name": f"{asset.asset_id}_{level.name}_bark",
                                             "mesh": writer.mesh(f"{level.name}_bark", prim)}))
                if level.skeleton.n_leaves:
                    children += _leaves_nodes(writer, asset, level, materials, variant_maps, instanced)
                if level.twigs is not None:
                    children.append(writer.node({"name": f"{asset.asset_id}_{level.name}_twigs",
                                                 "mesh": writer.mesh(f"{level.name}_twigs",
                                                                     _twig_primitive(writer, level, materials))}))
        node.update({"children": children, "extras": {"switch_px": level.switch_px, "triangles": level.n_triangles}})
        if level.name == "IMPOSTOR" and asset.impostor.layout():
            # An octahedral impostor: what a shader needs to pick its frames (the crossed planes need nothing).
            node["extras"]["impostor"] = asset.impostor.layout()
        level_nodes.append(writer.node(node))
    root = writer.nodes[level_nodes[0]]
    root["extensions"] = {"MSFT_lod": {"ids": level_nodes[1:]}}
    # Screen coverage at which each level stops being drawn: the next level's switch size over the screen.
    coverages = [lv.switch_px / SCREEN_HEIGHT_PX for lv in asset.levels[1:]] + [0.0]
    root["extras"].update({"MSFT_screencoverage": coverages, "asset_id": asset.asset_id})
    head = {"asset": {"version": "2.0", "generator": "treefarm farm.library"},
            "extensionsUsed": EXTENSIONS if instanced else [e for e in EXTENSIONS if e != "EXT_mesh_gpu_instancing"],
            "extensions": {"KHR_materials_variants": {"variants": [{"name": s} for s in SEASONS]}},
            "scene": 0, "scenes": [{"name": asset.asset_id, "nodes": [level_nodes[0]]}]}
    if skins:
        head["skins"] = skin_entries
        head["animations"] = [wind_animation(writer, asset.wind_clip, level_joints, lean_node)]
    return writer, head


def _twig_primitive(writer: GlbWriter, level, materials) -> dict:
    """The level's twig cluster cards, their season variants mapping the twig atlas of each season."""
    twigs = level.twigs
    return _primitive(writer, twigs.vertices, twigs.normals, twigs.uvs, twigs.faces, materials["twigs_summer"],
                      {"_WIND": (level.twig_wind, "VEC4"), "_WIND_PIVOT": (z_up_to_y_up(level.twig_pivot), "VEC3")},
                      [{"material": materials[f"twigs_{season}"], "variants": [i]}
                       for i, season in enumerate(SEASONS)], tangents=twigs.tangents)


def _skinned_level(writer: GlbWriter, asset, level, skin, bark_prim: dict, materials, variant_maps,
                   instanced: bool, node: dict) -> tuple[list[int], list[int]]:
    """A level with skeletal wind: its node takes one skinned mesh (bark, twig cards and, not instanced, the
    leaves), and its children are the joints, each holding the instanced leaf cards that move with it. Returns
    (children, joint nodes in rig order)."""
    prims = [add_skin_attributes(writer, bark_prim, skin.bark_joints, skin.bark_weights)]
    if level.twigs is not None:
        prims.append(add_skin_attributes(writer, _twig_primitive(writer, level, materials), skin.twig_joints,
                                         skin.twig_weights))
    joints = joint_nodes(writer, asset.wind_rig, "wind")
    if level.skeleton.n_leaves:
        if instanced:
            for joint, leaves in _leaves_nodes(writer, asset, level, materials, variant_maps, True, skin.leaf_joint):
                writer.nodes[joints[joint]].setdefault("children", []).append(leaves)
        elif level.leaf_outline is not None:  # single leaves as their outline polygons, clumps as cards
            for _, prim, chosen, per_card in _flat_cutout_primitives(writer, level, materials, variant_maps):
                prims.append(_rigidly_skinned(writer, prim, np.repeat(skin.leaf_joint[chosen], per_card)))
        else:
            flat = _flat_leaves_primitive(writer, level, materials, variant_maps)
            prims.append(_rigidly_skinned(writer, flat, np.repeat(skin.leaf_joint, 4)))
    # Named as the level's bark node is without wind: Blender names the skinned mesh's object after the mesh (the
    # level's node becomes its armature), and the FBX files keep that name.
    mesh = writer.mesh(f"{asset.asset_id}_{level.name}_bark", prims[0])
    writer.meshes[mesh]["primitives"] += prims[1:]
    node["mesh"] = mesh
    return [joints[0]], joints


def _rigidly_skinned(writer: GlbWriter, primitive: dict, joint: np.ndarray) -> dict:
    """The primitive skinned wholly to one joint per vertex (`joint` (V,)): a leaf moves with its joint."""
    weights = np.zeros((len(joint), 4), np.float32)
    weights[:, 0] = 1.0
    return add_skin_attributes(writer, primitive, np.stack([joint] + [np.zeros_like(joint)] * 3, axis=1), weights)


def _flat_leaves_primitive(writer: GlbWriter, level, materials, variant_maps) -> dict:
    """The level's leaf cards as one plain primitive, each card's UVs in its own tile."""
    part = level.mesh.leaves
    per_vertex = {"_WIND": (np.repeat(level.leaf_wind, 4, axis=0), "VEC4"),
                  "_WIND_PIVOT": (z_up_to_y_up(np.repeat(level.leaf_pivot, 4, axis=0)), "VEC3")}
    return _primitive(writer, part.vertices, part.normals, _leaf_tile_uvs(part.uvs, np.repeat(card_clumps(part), 4)),
                      part.faces, materials["summer"], per_vertex, variant_maps)


def _leaves_nodes(writer: GlbWriter, asset, level, materials, variant_maps, instanced: bool,
                  leaf_joint: np.ndarray | None = None):
    """The level's leaf card nodes. Flat: one `_leaves` mesh. Instanced: one node per card kind present, each
    drawing one card mesh at every instance of its kind (`_leaves`: cards that are one leaf, single-leaf tile;
    `_clumps`: cards that merge several, clump tile). With `leaf_joint` (M,) (skeletal wind): one such node
    per joint and kind, its instances placed from the joint's rest pivot, as (joint, node) pairs."""
    skeleton = level.skeleton
    clumps = card_clumps(level.mesh.leaves)
    outline = level.leaf_outline
    if not instanced and outline is not None:
        return [writer.node({"name": f"{asset.asset_id}_{level.name}_{kind}",
                             "mesh": writer.mesh(f"{level.name}_{kind}", prim)})
                for kind, prim, _, _ in _flat_cutout_primitives(writer, level, materials, variant_maps)]
    if not instanced:
        prim = _flat_leaves_primitive(writer, level, materials, variant_maps)
        return [writer.node({"name": f"{asset.asset_id}_{level.name}_leaves",
                             "mesh": writer.mesh(f"{level.name}_leaves", prim)})]
    # One card in its own frame (z along the leaf, normal +y); every card of a kind is an instance of it. Its
    # vertices are not turned to Y up: the instance rotations carry the whole frame change.
    card_normals = np.tile([0.0, 1.0, 0.0], (4, 1))
    translation, rotation, scale = leaf_instances(skeleton)
    groups = [(None, np.ones(len(clumps), bool))] if leaf_joint is None else \
        [(int(j), leaf_joint == j) for j in np.unique(leaf_joint)]
    origin = np.zeros((len(clumps), 3)) if leaf_joint is None else asset.wind_rig.position[leaf_joint]
    # Many groups (one per joint): every card's rotation turned once.
    turned = None if leaf_joint is None else unit_quaternions(Z_UP_TO_Y_UP @ rotation).astype(np.float32)
    nodes = []
    for clump, kind in ((False, "leaves"), (True, "clumps")):
        if not (clumps == clump).any():
            continue
        if outline is not None and not clump:  # the leaf's outline polygon in the card's frame, opaque
            k = len(outline.uvs)
            normals = np.tile([0.0, 1.0, 0.0], (k, 1))
            card = _primitive(writer, _card_to_local(outline.card_points), _card_to_local(normals),
                              _leaf_tile_uvs(outline.uvs, np.zeros(k, bool)), outline.faces, materials["cutout_summer"],
                              {"_WIND": (np.zeros((k, 4)), "VEC4"), "_WIND_PIVOT": (np.zeros((k, 3)), "VEC3")},
                              _cutout_maps(materials))
        else:
            card = _primitive(writer, _card_to_local(LEAF_CARD_CORNERS), _card_to_local(card_normals),
                              _leaf_tile_uvs(CARD_UVS, np.full(4, clump)), CARD_FACES, materials["summer"],
                              {"_WIND": (np.zeros((4, 4)), "VEC4"), "_WIND_PIVOT": (np.zeros((4, 3)), "VEC3")},
                              variant_maps)
        card_mesh = writer.mesh(f"{level.name}_{CARD_MESH_KINDS[kind]}_card", card)
        for joint, members in groups:
            chosen = members & (clumps == clump)
            if not chosen.any():
                continue
            attributes = {
                "TRANSLATION": writer.floats((translation[chosen] - origin[chosen]) @ Z_UP_TO_Y_UP.T, "VEC3", None),
                "ROTATION": writer.floats(turned[chosen] if turned is not None else
                                          unit_quaternions(Z_UP_TO_Y_UP @ rotation[chosen]).astype(np.float32),
                                          "VEC4", None),
                "SCALE": writer.floats(scale[chosen], "VEC3", None),
                "_WIND": writer.floats(level.leaf_wind[chosen], "VEC4", None),
                "_WIND_PIVOT": writer.floats(z_up_to_y_up(level.leaf_pivot[chosen]), "VEC3", None),
            }
            name = f"{asset.asset_id}_{level.name}_{kind}" + ("" if joint is None else
                                                             f"_{asset.wind_rig.names[joint]}")
            entry = writer.node({"name": name, "mesh": card_mesh,
                                 "extensions": {"EXT_mesh_gpu_instancing": {"attributes": attributes}}})
            nodes.append(entry if joint is None else (joint, entry))
    return nodes


def _flat_cutout_primitives(writer: GlbWriter, level, materials, variant_maps) -> list[tuple]:
    """Baked leaves of a `cutout` level: `leaves`, every single-leaf card's outline polygon (opaque), then
    `clumps`, the cards that merge several leaves (alpha-tested clump tile), when the level has any. Per kind
    present: (kind, primitive, its cards (M,) bool, vertices per card)."""
    part, out = level.mesh.leaves, []
    clumps = card_clumps(part)
    for clump, kind in ((False, "leaves"), (True, "clumps")):
        chosen = clumps == clump
        if not chosen.any():
            continue
        if clump:
            picked = np.repeat(chosen, 4)
            shape = MeshPart(part.vertices[picked], CARD_FACES[None] + 4 * np.arange(chosen.sum())[:, None, None],
                             part.normals[picked], _leaf_tile_uvs(part.uvs[picked], np.ones(picked.sum(), bool)))
            material, maps = materials["summer"], variant_maps
        else:
            shape = outline_leaves(part, level.leaf_outline, chosen)
            shape = MeshPart(shape.vertices, shape.faces, shape.normals,
                             _leaf_tile_uvs(shape.uvs, np.zeros(shape.n_vertices, bool)))
            material, maps = materials["cutout_summer"], _cutout_maps(materials)
        per_card = shape.n_vertices // int(chosen.sum())
        wind = {"_WIND": (np.repeat(level.leaf_wind[chosen], per_card, axis=0), "VEC4"),
                "_WIND_PIVOT": (z_up_to_y_up(np.repeat(level.leaf_pivot[chosen], per_card, axis=0)), "VEC3")}
        out.append((kind, _primitive(writer, shape.vertices, shape.normals, shape.uvs, shape.faces, material, wind,
                                     maps), chosen, per_card))
    return out


def _cutout_maps(materials) -> list[dict]:
    """KHR_materials_variants mappings of the opaque outline polygons: each season's `leaf_cutout_<season>`."""
    return [{"material": materials[f"cutout_{season}"], "variants": [i]} for i, season in enumerate(SEASONS)]


def _card_to_local(vectors: np.ndarray) -> np.ndarray:
    """Card-frame vectors, pre-turned so that `GlbWriter.triangles`' Z-up to Y-up turn leaves them unchanged."""
    v = np.asarray(vectors, np.float64)
    return np.stack([v[:, 0], -v[:, 2], v[:, 1]], axis=1)
