"""The asset GLB: every level of detail and the impostor as named nodes (MSFT_lod on the root, screen coverages
in its extras), leaves as instanced cards (EXT_mesh_gpu_instancing: one card for single leaves, one for
clumps), seasons as KHR_materials_variants, wind attributes `_WIND`/`_WIND_PIVOT`, PBR bark and a leaf atlas
with alpha.

In: a LibraryAsset. Out: GLB bytes (Y up, metres); same asset, same bytes. `instanced=False` bakes the leaves
into plain triangles (to measure what instancing saves).
"""
from __future__ import annotations

import json
import struct

import numpy as np

from species.meshing.gltf import _BinaryBuffer, z_up_to_y_up
from species.meshing.tubes_and_cards import _CARD_FACES, _CARD_UVS
from species.studio.pbr_textures import SEASONS
from species.studio.lod import card_clumps
from species.skeleton import LEAF_CARD_CORNERS
from .png_cache import encode_png

from .asset import LibraryAsset, leaf_instances

__all__ = ["asset_to_glb", "glb_size", "SCREEN_HEIGHT_PX", "EXTENSIONS"]

_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
_LINEAR, _LINEAR_MIPMAP_LINEAR, _REPEAT, _CLAMP = 9729, 9987, 10497, 33071
# MSFT_screencoverage values are switch sizes over this screen height (renderers.impostor's reference screen).
SCREEN_HEIGHT_PX = 1080
EXTENSIONS = ["EXT_mesh_gpu_instancing", "KHR_materials_variants", "MSFT_lod"]
# Our Z-up world to glTF's Y-up frame, as a rotation matrix (same as species.gltf.z_up_to_y_up).
_Z_TO_Y = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def _quaternions(rotation: np.ndarray) -> np.ndarray:
    """(M, 4) float32 unit quaternions (x, y, z, w) of rotation matrices (M, 3, 3)."""
    from scipy.spatial.transform import Rotation

    quat = Rotation.from_matrix(rotation).as_quat()
    quat[quat[:, 3] < 0] *= -1.0  # one sign per rotation, so the bytes do not depend on scipy's choice
    return (quat / np.linalg.norm(quat, axis=1, keepdims=True)).astype(np.float32)


class _SizeOnlyBuffer(_BinaryBuffer):
    """The views and accessors a _BinaryBuffer would hold, counting bytes without copying any."""

    def view(self, data: bytes | int, target: int | None = None) -> int:
        return self._record_view(data if isinstance(data, int) else len(data), target)

    def _payload(self, array: np.ndarray) -> int:
        return int(array.nbytes)

    def tobytes(self) -> bytes:
        raise TypeError("a size-only buffer holds no bytes")


class _Writer:
    def __init__(self, size_only: bool = False) -> None:
        self.buffer = _SizeOnlyBuffer() if size_only else _BinaryBuffer()
        self.images, self.textures, self.samplers, self.materials = [], [], [], []
        self.meshes, self.nodes = [], []

    def texture(self, name: str, image: np.ndarray, wrap: int) -> int:
        self.samplers.append({"magFilter": _LINEAR, "minFilter": _LINEAR_MIPMAP_LINEAR, "wrapS": wrap, "wrapT": wrap})
        self.images.append({"name": name, "bufferView": self.buffer.view(encode_png(image)), "mimeType": "image/png"})
        self.textures.append({"sampler": len(self.samplers) - 1, "source": len(self.images) - 1})
        return len(self.textures) - 1

    def material(self, entry: dict) -> int:
        self.materials.append(entry)
        return len(self.materials) - 1

    def vec(self, array: np.ndarray, kind: str, target: int | None = _ARRAY_BUFFER, bounds: bool = False) -> int:
        return self.buffer.accessor(np.ascontiguousarray(array, np.float32), kind, target, with_bounds=bounds)

    def primitive(self, vertices, normals, uvs, faces, material: int, extra: dict | None = None,
                  variants: list[dict] | None = None) -> dict:
        uv = np.asarray(uvs, np.float32).copy()
        uv[:, 1] = 1.0 - uv[:, 1]
        index_type = np.uint16 if len(vertices) <= 0xFFFF else np.uint32
        attributes = {"POSITION": self.vec(z_up_to_y_up(vertices), "VEC3", bounds=True),
                      "NORMAL": self.vec(z_up_to_y_up(normals), "VEC3"), "TEXCOORD_0": self.vec(uv, "VEC2")}
        for name, (array, kind) in (extra or {}).items():
            attributes[name] = self.vec(array, kind)
        entry = {"attributes": attributes, "material": material, "mode": 4,
                 "indices": self.buffer.accessor(np.asarray(faces).reshape(-1).astype(index_type), "SCALAR",
                                                 _ELEMENT_ARRAY_BUFFER)}
        if variants:
            entry["extensions"] = {"KHR_materials_variants": {"mappings": variants}}
        return entry

    def mesh(self, name: str, primitive: dict) -> int:
        self.meshes.append({"name": name, "primitives": [primitive]})
        return len(self.meshes) - 1

    def node(self, entry: dict) -> int:
        self.nodes.append(entry)
        return len(self.nodes) - 1


def _materials(writer: _Writer, asset: LibraryAsset) -> dict[str, int]:
    maps = asset.bark_maps
    bark = writer.material({"name": "bark", "pbrMetallicRoughness": {
        "baseColorTexture": {"index": writer.texture("bark_base_color", maps.base_color, _REPEAT)},
        "metallicRoughnessTexture": {"index": writer.texture("bark_roughness_metallic", maps.roughness_metallic,
                                                             _REPEAT)},
        "metallicFactor": 1.0, "roughnessFactor": 1.0},
        "normalTexture": {"index": writer.texture("bark_normal", maps.normal, _REPEAT)}})
    out = {"bark": bark}
    for season in SEASONS:
        entry = {"name": f"leaves_{season}", "alphaMode": "MASK", "alphaCutoff": 0.5, "doubleSided": True}
        if season == "bare":  # no leaves: everything cut away
            entry["pbrMetallicRoughness"] = {"baseColorFactor": [1.0, 1.0, 1.0, 0.0], "metallicFactor": 0.0}
        else:
            entry["pbrMetallicRoughness"] = {
                "baseColorTexture": {"index": writer.texture(f"leaf_atlas_{season}", asset.leaf_atlases[season],
                                                             _CLAMP)},
                "metallicFactor": 0.0, "roughnessFactor": 0.7}
        out[season] = writer.material(entry)
    atlas = asset.impostor
    out["impostor"] = writer.material({
        "name": "impostor", "alphaMode": "MASK", "alphaCutoff": 0.5, "doubleSided": True,
        "pbrMetallicRoughness": {"baseColorTexture": {"index": writer.texture("impostor_albedo", atlas.albedo,
                                                                              _CLAMP)},
                                 "metallicFactor": 0.0, "roughnessFactor": 0.8},
        "normalTexture": {"index": writer.texture("impostor_normal", atlas.normal, _CLAMP)}})
    return out


def _leaf_tile_uvs(uvs: np.ndarray, clump: np.ndarray) -> np.ndarray:
    """Card UVs (V, 2) into the atlas: the left tile (one leaf) where `clump` (V,) bool is False, the right (a
    clump of leaves) where it is True."""
    out = np.asarray(uvs, np.float64).copy()
    out[:, 0] = 0.5 * out[:, 0] + 0.5 * np.asarray(clump, np.float64)
    return out


def asset_to_glb(asset: LibraryAsset, instanced: bool = True) -> bytes:
    """GLB bytes of the asset (see the module docstring). Scene: the LOD0 node; LOD1.. and IMPOSTOR are nodes
    outside the scene, listed by the root's MSFT_lod in order of decreasing detail."""
    json_bytes, writer = _document(asset, instanced, size_only=False)
    binary = writer.buffer.tobytes()
    chunks = struct.pack("<II", len(json_bytes), 0x4E4F534A) + json_bytes
    chunks += struct.pack("<II", len(binary), 0x004E4942) + binary
    return struct.pack("<III", 0x46546C67, 2, 12 + len(chunks)) + chunks


def glb_size(asset: LibraryAsset, instanced: bool = True) -> int:
    """len(asset_to_glb(asset, instanced)), exactly, without packing the binary chunk (the same JSON is
    built; buffer views are counted, not copied): what the catalog reports for the file without instancing."""
    json_bytes, writer = _document(asset, instanced, size_only=True)
    return 12 + 8 + len(json_bytes) + 8 + writer.buffer.size


def _document(asset: LibraryAsset, instanced: bool, size_only: bool) -> tuple[bytes, _Writer]:
    """The padded JSON chunk and the writer holding the binary chunk's views."""
    writer = _Writer(size_only)
    materials = _materials(writer, asset)
    variant_maps = [{"material": materials[season], "variants": [i]} for i, season in enumerate(SEASONS)]
    level_nodes = []
    for level in asset.levels:
        children = []
        mesh = level.mesh
        if level.name == "IMPOSTOR":
            part = mesh.bark
            prim = writer.primitive(part.vertices, part.normals, part.uvs, part.faces, materials["impostor"])
            children.append(writer.node({"name": f"{asset.asset_id}_IMPOSTOR_card", "mesh": writer.mesh("impostor", prim)}))
        else:
            bark = mesh.bark
            prim = writer.primitive(bark.vertices, bark.normals, bark.uvs, bark.faces, materials["bark"],
                                    {"_WIND": (level.bark_wind, "VEC4"),
                                     "_WIND_PIVOT": (z_up_to_y_up(level.bark_pivot), "VEC3")})
            children.append(writer.node({"name": f"{asset.asset_id}_{level.name}_bark",
                                         "mesh": writer.mesh(f"{level.name}_bark", prim)}))
            if level.skeleton.n_leaves:
                children += _leaves_nodes(writer, asset, level, materials, variant_maps, instanced)
        node = {"name": f"{asset.asset_id}_{level.name}", "children": children,
                "extras": {"switch_px": level.switch_px, "triangles": level.n_triangles}}
        level_nodes.append(writer.node(node))
    root = writer.nodes[level_nodes[0]]
    root["extensions"] = {"MSFT_lod": {"ids": level_nodes[1:]}}
    # Screen coverage at which each level stops being drawn: the next level's switch size over the screen.
    coverages = [lv.switch_px / SCREEN_HEIGHT_PX for lv in asset.levels[1:]] + [0.0]
    root["extras"].update({"MSFT_screencoverage": coverages, "asset_id": asset.asset_id})
    document = {"asset": {"version": "2.0", "generator": "treefarm farm.library"},
                "extensionsUsed": EXTENSIONS if instanced else [e for e in EXTENSIONS if e != "EXT_mesh_gpu_instancing"],
                "extensions": {"KHR_materials_variants": {"variants": [{"name": s} for s in SEASONS]}},
                "scene": 0, "scenes": [{"name": asset.asset_id, "nodes": [level_nodes[0]]}],
                "nodes": writer.nodes, "meshes": writer.meshes, "materials": writer.materials,
                "textures": writer.textures, "images": writer.images, "samplers": writer.samplers,
                "accessors": writer.buffer.accessors, "bufferViews": writer.buffer.views,
                "buffers": [{"byteLength": writer.buffer.size}]}
    json_bytes = json.dumps(document, separators=(",", ":"), ensure_ascii=True).encode("ascii")
    json_bytes += b" " * ((-len(json_bytes)) % 4)
    return json_bytes, writer


def _leaves_nodes(writer: _Writer, asset, level, materials, variant_maps, instanced: bool) -> list[int]:
    """The level's leaf card nodes. Flat: one `_leaves` mesh, each card's UVs in its own tile. Instanced: one
    node per card kind present, each drawing one card mesh at every instance of its kind (`_leaves`: cards
    that are one leaf, single-leaf tile; `_clumps`: cards that merge several, clump tile)."""
    skeleton, part = level.skeleton, level.mesh.leaves
    clumps = card_clumps(part)
    if not instanced:
        per_vertex = {"_WIND": (np.repeat(level.leaf_wind, 4, axis=0), "VEC4"),
                      "_WIND_PIVOT": (z_up_to_y_up(np.repeat(level.leaf_pivot, 4, axis=0)), "VEC3")}
        prim = writer.primitive(part.vertices, part.normals, _leaf_tile_uvs(part.uvs, np.repeat(clumps, 4)),
                                part.faces, materials["summer"], per_vertex, variant_maps)
        return [writer.node({"name": f"{asset.asset_id}_{level.name}_leaves",
                             "mesh": writer.mesh(f"{level.name}_leaves", prim)})]
    # One card in its own frame (z along the leaf, normal +y); every card of a kind is an instance of it. Its
    # vertices are not turned to Y up: the instance rotations carry the whole frame change.
    card_normals = np.tile([0.0, 1.0, 0.0], (4, 1))
    translation, rotation, scale = leaf_instances(skeleton)
    nodes = []
    for clump, kind in ((False, "leaves"), (True, "clumps")):
        chosen = clumps == clump
        if not chosen.any():
            continue
        card = writer.primitive(_card_to_local(LEAF_CARD_CORNERS), _card_to_local(card_normals),
                                _leaf_tile_uvs(_CARD_UVS, np.full(4, clump)), _CARD_FACES, materials["summer"],
                                {"_WIND": (np.zeros((4, 4)), "VEC4"), "_WIND_PIVOT": (np.zeros((4, 3)), "VEC3")},
                                variant_maps)
        attributes = {
            "TRANSLATION": writer.vec(translation[chosen] @ _Z_TO_Y.T, "VEC3", None),
            "ROTATION": writer.vec(_quaternions(_Z_TO_Y @ rotation[chosen]), "VEC4", None),
            "SCALE": writer.vec(scale[chosen], "VEC3", None),
            "_WIND": writer.vec(level.leaf_wind[chosen], "VEC4", None),
            "_WIND_PIVOT": writer.vec(z_up_to_y_up(level.leaf_pivot[chosen]), "VEC3", None),
        }
        nodes.append(writer.node({"name": f"{asset.asset_id}_{level.name}_{kind}",
                                  "mesh": writer.mesh(f"{level.name}_{kind[:-1]}_card", card),
                                  "extensions": {"EXT_mesh_gpu_instancing": {"attributes": attributes}}}))
    return nodes


def _card_to_local(vectors: np.ndarray) -> np.ndarray:
    """Card-frame vectors, pre-turned so that `primitive`'s Z-up to Y-up turn leaves them unchanged."""
    v = np.asarray(vectors, np.float64)
    return np.stack([v[:, 0], -v[:, 2], v[:, 1]], axis=1)
