"""A skeleton as triangles: bark tubes and leaf cards, their procedural textures, the glTF (GLB) and OBJ
writers, and a tree's files on disk (`write_tree`).
"""
from __future__ import annotations

from .tubes_and_cards import (bark_part, build_mesh, CARD_FACES, CARD_UVS, DEFAULT_RADIAL_SEGMENTS, leaf_part,
    MeshBuildError, radial_segments)
from .png import png_bytes
from .textures import (bark_colour, bark_png, bark_texture, BARK_TEXTURE_SEED, fissure_depth, leaf_png, leaf_texture,
    linear_to_srgb, periodic_noise)
from .gltf import (ARRAY_BUFFER, CLAMP_TO_EDGE, ELEMENT_ARRAY_BUFFER, GlbBuffer, GlbError, GlbWriter, read_accessor,
    node_matrix, read_glb_chunks, read_glb_json, REPEAT, tree_mesh_to_glb, TRIANGLES, z_up_to_y_up, Z_UP_TO_Y_UP)
from .obj import ObjError, tree_mesh_to_obj
from .tree_files import write_tree
from .ascii_numbers import AsciiNumberError, FIXED6_MAX_MAGNITUDE, fixed6_rows, INT_MAX_MAGNITUDE, int_rows
from ..tree_mesh import MESH_WRITERS

MESH_WRITERS.update(glb=tree_mesh_to_glb, obj=tree_mesh_to_obj)

__all__ = [
    "build_mesh", "bark_part", "leaf_part", "radial_segments", "MeshBuildError", "DEFAULT_RADIAL_SEGMENTS",
    "CARD_UVS", "CARD_FACES", "png_bytes",
    "bark_texture", "leaf_texture", "bark_png", "leaf_png", "linear_to_srgb", "periodic_noise", "fissure_depth",
    "bark_colour", "BARK_TEXTURE_SEED",
    "tree_mesh_to_glb", "node_matrix", "GlbBuffer", "GlbWriter", "read_glb_json", "read_glb_chunks", "read_accessor",
    "z_up_to_y_up", "Z_UP_TO_Y_UP", "GlbError", "ARRAY_BUFFER", "ELEMENT_ARRAY_BUFFER", "REPEAT", "CLAMP_TO_EDGE",
    "TRIANGLES",
    "tree_mesh_to_obj", "ObjError", "fixed6_rows", "int_rows", "AsciiNumberError", "FIXED6_MAX_MAGNITUDE",
    "INT_MAX_MAGNITUDE", "write_tree",
]
