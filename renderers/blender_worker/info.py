"""Job kind `info`: import a GLB and report what Blender sees (objects, parts, vertices, triangles, bounds,
armatures and actions).

Job keys: glb (path). Result: the `scene.mesh_stats` dictionary with `scene.animation_stats`'.
"""
from __future__ import annotations

from fbx import import_checked_glb
from scene import animation_stats, mesh_stats, require, reset_scene


def run(job: dict, out_dir: str) -> dict:
    reset_scene()
    objects = import_checked_glb(require(job, "glb"))
    return {**mesh_stats(objects), **animation_stats(objects)}
