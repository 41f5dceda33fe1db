"""A meshed tree written to disk: one GLB file, or the OBJ with its MTL and texture PNGs beside it.

In: a TreeMesh, the file to write and its format ("glb" or "obj"). Out: the files written, the named file first.
"""
from __future__ import annotations

from pathlib import Path

from ..errors import user_path
from ..tree_mesh import TreeMesh

__all__ = ["write_tree"]


def write_tree(mesh: TreeMesh, path: Path, fmt: str) -> list[Path]:
    """Write one tree as `path` (GLB) or as OBJ + MTL + textures beside it (named after `mesh.name`); returns the
    files written. A file error is a `PathError` naming `path`; missing parent folders are made."""
    files = {path.name: mesh.to_glb()} if fmt == "glb" else mesh.to_obj()
    with user_path(path, "write"):
        path.parent.mkdir(parents=True, exist_ok=True)
        for name, data in files.items():
            (path.parent / name).write_bytes(data)
    return [path.parent / name for name in files]
