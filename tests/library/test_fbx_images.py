"""Images of the library's FBX files: each distinct image is embedded once, Blender's importer brings it back
once per colour space, and every material of every LOD keeps its base colour, normal and alpha textures.

The GLB is laid out as the library's: two LOD nodes sharing their bark and leaf materials, two leaf materials
sharing one RGBA atlas (cut out by alpha, MASK). Blender runs for real (`.venv-blender`, built by `make env`).
"""
from __future__ import annotations

import hashlib
import re

import numpy as np
import pytest

from renderers.blender_assets import export_fbx_batch, read_fbx
from species.meshing.gltf import REPEAT, TRIANGLES, GlbWriter
from species.meshing.png import png_bytes

LODS = ("LOD0", "LOD1")
PNG_START, PNG_END = b"\x89PNG\r\n\x1a\n", b"IEND\xaeB`\x82"


def _pngs() -> dict[str, bytes]:
    """Three distinct 16 x 16 images: bark colour (RGB), bark normal (RGB), leaf atlas (RGBA, half cut out)."""
    rows, cols = np.indices((16, 16), dtype=np.uint8)
    bark = np.stack([rows * 9, cols * 5, np.full_like(rows, 40)], axis=-1)
    normal = np.stack([np.full_like(rows, 128), np.full_like(rows, 128), np.full_like(rows, 255)], axis=-1)
    leaf = np.stack([cols * 3, 100 + rows * 8, np.full_like(rows, 30), np.where(cols < 8, 255, 0)], axis=-1)
    return {"bark_base_color": png_bytes(bark.astype(np.uint8)), "bark_normal": png_bytes(normal.astype(np.uint8)),
            "leaf_atlas": png_bytes(leaf.astype(np.uint8))}


def _library_like_glb(pngs: dict[str, bytes]) -> bytes:
    """Scene roots LOD0 and LOD1, each with a bark box and two leaf cards (one per leaf material)."""
    writer = GlbWriter()
    textures = {name: writer.texture(name, data, REPEAT) for name, data in pngs.items()}
    bark = writer.material({"name": "bark", "pbrMetallicRoughness": {
        "baseColorTexture": {"index": textures["bark_base_color"]}},
        "normalTexture": {"index": textures["bark_normal"]}})
    leaves = [writer.material({"name": name, "alphaMode": "MASK", "alphaCutoff": 0.5, "doubleSided": True,
                               "pbrMetallicRoughness": {"baseColorTexture": {"index": textures["leaf_atlas"]}}})
              for name in ("leaves", "leaves_clumps")]
    card = np.array([[0, 0, 1], [1, 0, 1], [1, 0, 2], [0, 0, 2]], np.float32)
    uvs = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    faces = np.array([[0, 1, 2], [0, 2, 3]])

    def part(name: str, vertices: np.ndarray, material: int) -> int:
        attributes, indices = writer.triangles(vertices, np.tile([0.0, -1.0, 0.0], (4, 1)), uvs, faces)
        mesh = writer.mesh(name, {"attributes": attributes, "indices": indices, "material": material,
                                  "mode": TRIANGLES})
        return writer.node({"name": name, "mesh": mesh})

    roots = []
    for lod in LODS:
        children = [part(f"{lod}_bark", card * [0.2, 1, 0.5] - [0.1, 0, 0.5], bark),
                    part(f"{lod}_leaves", card + [0.5, 0, 0], leaves[0]),
                    part(f"{lod}_clumps", card - [1.5, 0, 0], leaves[1])]
        roots.append(writer.node({"name": lod, "children": children}))
    return writer.to_glb({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": roots}]})


def _embedded_pngs(fbx: bytes) -> list[str]:
    """sha256 of every PNG file stored whole in the FBX's bytes, in file order."""
    return [hashlib.sha256(m.group(0)).hexdigest()
            for m in re.finditer(re.escape(PNG_START) + b".*?" + re.escape(PNG_END), fbx, re.DOTALL)]


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """({name: png sha256}, {lod: (fbx bytes, read back)}): one FBX per LOD node of the library-like GLB."""
    pngs = _pngs()
    folder = tmp_path_factory.mktemp("fbx_images")
    glb = folder / "tree.glb"
    glb.write_bytes(_library_like_glb(pngs))
    rows = export_fbx_batch([{"glb": glb, "fbx": folder / f"tree_{lod}.fbx", "node": lod} for lod in LODS])
    digests = {name: hashlib.sha256(data).hexdigest() for name, data in pngs.items()}
    return digests, {lod: (open(row["fbx"], "rb").read(), read_fbx(row["fbx"])) for lod, row in zip(LODS, rows)}


@pytest.mark.parametrize("lod", LODS)
def test_fbx_embeds_each_distinct_image_once(exported, lod):
    digests, files = exported
    embedded = _embedded_pngs(files[lod][0])
    assert sorted(embedded) == sorted(digests.values())  # the GLB's own PNG bytes, none twice, none missing


@pytest.mark.parametrize("lod", LODS)
def test_fbx_imports_each_image_once_but_blenders_alpha_copies(exported, lod):
    """Blender keeps one colour space per image datablock, so its FBX importer reads an RGBA base colour's alpha
    through a Non-Color copy of that image, one per material (Blender 5.0, whatever the file holds); every
    other image comes back once."""
    digests, files = exported
    read = files[lod][1]
    sockets: dict[str, set] = {}
    for bindings in read["bindings"].values():
        for socket, names in bindings.items():
            for name in names:
                sockets.setdefault(name, set()).add(socket)
    copies = [row for row in read["images"] if row["colorspace"] == "Non-Color" and sockets[row["name"]] == {"Alpha"}]
    kept = [row["sha256"] for row in read["images"] if row not in copies]
    assert sorted(kept) == sorted(digests.values()), read["images"]
    assert {row["sha256"] for row in copies} == {digests["leaf_atlas"]}


@pytest.mark.parametrize("lod", LODS)
def test_fbx_materials_keep_their_base_colour_normal_and_alpha_textures(exported, lod):
    digests, files = exported
    read = files[lod][1]
    content = {row["name"]: row["sha256"] for row in read["images"]}
    bound = {material: {socket: {content[name] for name in names} for socket, names in sockets.items()}
             for material, sockets in read["bindings"].items()}
    leaf = {digests["leaf_atlas"]}
    assert bound == {"bark": {"Base Color": {digests["bark_base_color"]}, "Normal": {digests["bark_normal"]}},
                     "leaves": {"Base Color": leaf, "Alpha": leaf},
                     "leaves_clumps": {"Base Color": leaf, "Alpha": leaf}}
    assert {row["name"]: row["materials"] for row in read["objects"]} == {
        f"{lod}_bark": ["bark"], f"{lod}_leaves": ["leaves"], f"{lod}_clumps": ["leaves_clumps"]}
