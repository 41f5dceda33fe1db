"""Wavefront OBJ writer for a TreeMesh: the OBJ text, its MTL and the two texture PNGs, by file name.

In: a TreeMesh (Z up). Out: {"<name>.obj", "<name>.mtl", "<name>_bark.png", "<name>_leaf.png"} bytes, Y up.
"""
from __future__ import annotations

import re

import numpy as np

from .ascii_numbers import AsciiNumberError, fixed6_rows, int_rows
from ..errors import TreefarmError
from .gltf import z_up_to_y_up
from .textures import bark_png, leaf_png
from ..tree_mesh import MeshPart, TreeMesh

__all__ = ["tree_mesh_to_obj", "ObjError"]

# File names are built from the tree's name, so it must be a plain file-name stem.
_NAME_PATTERN = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.\-]*")


class ObjError(TreefarmError):
    """A tree that cannot be written as OBJ (a name that is not a plain file-name stem, a non-finite or huge value)."""


def _part_text(name: str, part: MeshPart, first_index: int) -> bytes:
    corners = (part.faces.astype(np.int64) + first_index).repeat(3, axis=1)  # v/vt/vn share one index
    try:
        return b"".join([
            f"o {name}\n".encode("ascii"),
            fixed6_rows("v", z_up_to_y_up(part.vertices)),
            fixed6_rows("vt", part.uvs),
            fixed6_rows("vn", z_up_to_y_up(part.normals)),
            f"usemtl {name}\ns 1\n".encode("ascii"),
            int_rows("f", corners, " // // //"),
        ])
    except AsciiNumberError as error:
        raise ObjError(f"{name} cannot be written as OBJ: {error}") from error


def tree_mesh_to_obj(tree: TreeMesh, compress_level: int = 9) -> dict[str, bytes]:
    """OBJ, MTL and textures of `tree`, by file name; write them side by side in one folder.

    OBJ is conventionally Y up, so positions and normals are turned from our Z-up world with
    (x, y, z) -> (x, z, -y), as in the GLB writer; UVs keep v up (OBJ convention). Two objects, "bark"
    and "leaves" (left out when empty), each with `usemtl` of its material. The MTL gives bark
    `map_Kd <name>_bark.png` and leaves `map_Kd`/`map_d <name>_leaf.png` (the leaf PNG's alpha is the
    cut-out). Texture names carry the tree's name so many trees can share a folder. Same tree, same bytes.
    `compress_level`: the textures' zlib level (9, the smallest files and the slowest; the asset library writes
    them at its own fast level).
    """
    if not isinstance(tree, TreeMesh):
        raise ObjError(f"tree_mesh_to_obj needs a TreeMesh; got {type(tree).__name__}")
    if not _NAME_PATTERN.fullmatch(tree.name):
        raise ObjError(f"tree name {tree.name!r} cannot name OBJ files: use letters, digits, '_', '-' and '.' "
                       f"(not first)")
    name = tree.name
    bark_file, leaf_file = f"{name}_bark.png", f"{name}_leaf.png"
    header = f"# treefarm tree {name}: metres, Y up (converted from the farm's Z up)\nmtllib {name}.mtl\n"
    obj = [header.encode("ascii")]
    first_index = 1  # OBJ indices are 1-based and global over the file
    for part_name, part in (("bark", tree.bark), ("leaves", tree.leaves)):
        if part.n_faces == 0:
            continue
        obj.append(_part_text(part_name, part, first_index))
        first_index += part.n_vertices
    mtl = (
        f"# treefarm materials for {name}\n"
        "newmtl bark\nKa 0 0 0\nKd 1 1 1\nKs 0 0 0\nNs 10\nd 1\nillum 1\n"
        f"map_Kd {bark_file}\n\n"
        "newmtl leaves\nKa 0 0 0\nKd 1 1 1\nKs 0 0 0\nNs 10\nd 1\nillum 1\n"
        f"map_Kd {leaf_file}\nmap_d {leaf_file}\n"
    )
    return {
        f"{name}.obj": b"".join(obj),
        f"{name}.mtl": mtl.encode("ascii"),
        bark_file: bark_png(tree.bark_color, compress_level),
        leaf_file: leaf_png(tree.leaf_color, compress_level),
    }
