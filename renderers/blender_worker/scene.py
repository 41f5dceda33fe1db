"""Scene plumbing shared by every job kind: an empty scene, GLB import, mesh statistics, part labels.

Runs inside Blender's Python (bpy); objects come back in Blender's world, which is ours (Z up, metres).
"""
from __future__ import annotations

import os

import bpy
from mathutils import Vector

__all__ = ["JobError", "require", "reset_scene", "import_glb", "mesh_objects", "mesh_stats", "animation_stats",
           "part_of", "PART_INDEX"]

# Mask values of the farm's renderers (renderers/maps.py, combine_parts): 0 background, 1 bark, 2 leaves.
PART_INDEX = {"bark": 1, "leaves": 2}


class JobError(ValueError):
    """A job file asks for something impossible (unknown kind, missing file, bad value); exit code 2."""


def require(job: dict, key: str, kind: type = str):
    """job[key], checked for presence and type; a miss raises JobError naming the key."""
    if key not in job:
        raise JobError(f"job {job.get('kind')!r} lacks the key {key!r}")
    value = job[key]
    if not isinstance(value, kind):
        raise JobError(f"job key {key!r} = {value!r} must be of type {kind.__name__}")
    return value


def reset_scene() -> bpy.types.Scene:
    """Factory settings with nothing in the scene (no cube, camera or light), so jobs never see each other."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy.context.scene


def import_glb(path: str) -> list:
    """Import a .glb/.gltf; the importer turns glTF's Y up into Blender's Z up. Returns the new objects."""
    if not os.path.isfile(path):
        raise JobError(f"glb {path!r} does not exist")
    before = set(bpy.data.objects)
    result = bpy.ops.import_scene.gltf(filepath=path)
    if "FINISHED" not in result:
        raise JobError(f"Blender's glTF importer could not read {path!r} ({result})")
    return [obj for obj in bpy.data.objects if obj not in before]


def mesh_objects(objects) -> list:
    return [obj for obj in objects if obj.type == "MESH"]


def part_of(obj) -> str:
    """'leaves' for an object whose object, mesh or material name says leaf/leaves/foliage, else 'bark'."""
    names = [obj.name, obj.data.name] + [m.name for m in obj.data.materials if m is not None]
    return "leaves" if any(k in n.lower() for n in names for k in ("leaf", "leaves", "foliage")) else "bark"


def mesh_stats(objects) -> dict:
    """Per mesh object: name, part, vertices, triangles, materials; totals; world bounds (2, 3) metres."""
    rows, lo, hi = [], [float("inf")] * 3, [float("-inf")] * 3
    for obj in mesh_objects(objects):
        mesh = obj.data
        mesh.calc_loop_triangles()
        rows.append({"name": obj.name, "part": part_of(obj), "vertices": len(mesh.vertices),
                     "triangles": len(mesh.loop_triangles),
                     "materials": [m.name for m in mesh.materials if m is not None]})
        for corner in obj.bound_box:
            world = obj.matrix_world @ Vector(corner)
            lo = [min(a, b) for a, b in zip(lo, world)]
            hi = [max(a, b) for a, b in zip(hi, world)]
    return {"objects": rows, "triangles": sum(r["triangles"] for r in rows),
            "vertices": sum(r["vertices"] for r in rows), "bounds": [lo, hi] if rows else None}


def animation_stats(objects) -> dict:
    """The armatures among `objects` (name, bones) and every action in the file (name, first and last frame,
    seconds at the scene's frame rate), with that frame rate."""
    scene = bpy.context.scene
    fps = scene.render.fps / scene.render.fps_base
    armatures = [{"name": obj.name, "bones": len(obj.data.bones)} for obj in objects if obj.type == "ARMATURE"]
    actions = []
    for action in bpy.data.actions:
        start, end = (float(v) for v in action.frame_range)
        actions.append({"name": action.name, "frames": [start, end], "seconds": (end - start) / fps})
    return {"armatures": armatures, "actions": actions, "fps": fps}
