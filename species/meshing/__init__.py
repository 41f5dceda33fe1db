"""A skeleton as triangles: bark tubes and leaf cards, their procedural textures, and the glTF (GLB) and OBJ
writers.
"""
from __future__ import annotations

from .tubes_and_cards import (bark_part, build_mesh, DEFAULT_RADIAL_SEGMENTS, leaf_part, MeshBuildError,
    radial_segments)
from .textures import bark_png, bark_texture, BARK_TEXTURE_SEED, leaf_png, leaf_texture, linear_to_srgb, png_bytes
from .gltf import GlbError, read_accessor, read_glb_chunks, read_glb_json, tree_mesh_to_glb, z_up_to_y_up
from .obj import ObjError, tree_mesh_to_obj
from .ascii_numbers import AsciiNumberError, FIXED6_MAX_MAGNITUDE, fixed6_rows, INT_MAX_MAGNITUDE, int_rows
from ..tree_mesh import MESH_WRITERS

MESH_WRITERS.update(glb=tree_mesh_to_glb, obj=tree_mesh_to_obj)

__all__ = [
    "build_mesh", "bark_part", "leaf_part", "radial_segments", "MeshBuildError", "DEFAULT_RADIAL_SEGMENTS",
    "bark_texture", "leaf_texture", "png_bytes", "bark_png", "leaf_png", "linear_to_srgb", "BARK_TEXTURE_SEED",
    "tree_mesh_to_glb", "read_glb_json", "read_glb_chunks", "read_accessor", "z_up_to_y_up", "GlbError",
    "tree_mesh_to_obj", "ObjError", "fixed6_rows", "int_rows", "AsciiNumberError", "FIXED6_MAX_MAGNITUDE",
    "INT_MAX_MAGNITUDE",
]
