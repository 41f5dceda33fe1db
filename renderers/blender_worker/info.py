"""Job kind `info`: import a GLB and report what Blender sees (objects, parts, vertices, triangles, bounds).

Job keys: glb (path). Result: the `scene.mesh_stats` dictionary.
"""
from __future__ import annotations

from scene import import_glb, mesh_stats, require, reset_scene


def run(job: dict, out_dir: str) -> dict:
    reset_scene()
    return mesh_stats(import_glb(require(job, "glb")))
