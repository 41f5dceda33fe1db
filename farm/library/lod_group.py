"""The engine LOD-group FBX of an asset: every level in one file, named `<id>_LOD0`, `<id>_LOD1`, ... with the
impostor last (Unity builds an LOD Group from those suffixes on import), textures embedded once, and the screen
sizes an engine needs, worked out from the library's switch sizes.

In: an asset's record (`asset.json` as `stage_asset_files` makes it) and its library folder. Out: the Blender
worker's export job for the file (`renderers.blender_assets.export_fbx_batch`), the record's `lod_group`
entry (level names, Unity transition heights, Unreal screen sizes), and the file Blender wrote given the FBX
LodGroup node Unreal needs (`fbx_lod_node`), its thresholds from the Unity transitions.
"""
from __future__ import annotations

import math

from .fbx_lod_node import add_lod_group_node
from .gltf_asset import SCREEN_HEIGHT_PX

__all__ = ["LOD_GROUP_FILE", "lod_group_names", "lod_group_job", "lod_group_entry", "unity_transitions",
           "unreal_screen_sizes", "lod_group_thresholds", "write_lod_group_node"]

LOD_GROUP_FILE = "{ident}.fbx"  # beside the asset's GLB and USD; the per-level files stay in fbx/


def lod_group_names(ident: str, count: int) -> list[str]:
    """`<id>_LOD0` ... `<id>_LOD{count - 1}`: the impostor, last, is one more level for the engine."""
    return [f"{ident}_LOD{i}" for i in range(count)]


def unity_transitions(switch_px, height_m: float, crown_radius_m: float) -> list[float]:
    """Unity LOD Group transition per level (screen-relative height below which the next level takes over),
    0 for the last (the impostor is never culled). Unity measures the group by the largest side of its bounds,
    the switch sizes by the tree's height: each switch height is scaled by that side over the height."""
    side = max(height_m, 2.0 * crown_radius_m) / height_m
    return [round(px / SCREEN_HEIGHT_PX * side, 4) for px in list(switch_px)[1:]] + [0.0]


def unreal_screen_sizes(switch_px, height_m: float, crown_radius_m: float) -> list[float]:
    """Unreal static mesh LOD screen size per level (from which it is drawn; LOD0 1.0). Unreal measures the
    bounding sphere's diameter on screen: each switch height is scaled by that diameter over the tree's height,
    the sphere taken round the box of the tree's height and crown diameter (a close bound, not Unreal's own)."""
    diameter = math.sqrt(height_m ** 2 + 2.0 * (2.0 * crown_radius_m) ** 2)
    return [1.0] + [round(px / SCREEN_HEIGHT_PX * diameter / height_m, 4) for px in list(switch_px)[1:]]


def lod_group_job(record: dict, location, folder: str) -> dict:
    """The export job of the asset's LOD-group FBX from its flat GLB (`record["files"]["glb_flat"]`): every
    level node (`<id>_<LEVEL>`) renamed `<id>_LOD<i>`. An asset with skeletal wind (`record["skeletal_wind"]`)
    exports them animated: each skinned level is its armature with its mesh, the impostor's lean node keyed,
    one take of the clip, as in the per-level files."""
    ident = record["id"]
    levels = [level["name"] for level in record["levels"]]
    return {"glb": location.path(record["files"]["glb_flat"]),
            "fbx": location.path(f"{folder}/{LOD_GROUP_FILE.format(ident=ident)}"),
            "nodes": [f"{ident}_{name}" for name in levels], "names": lod_group_names(ident, len(levels)),
            **({"animated": True} if "skeletal_wind" in record else {})}


def lod_group_entry(record: dict) -> dict:
    """asset.json's `lod_group`: the file's level names with the level each is, and the engines' screen sizes."""
    switch = [level["switch_px"] for level in record["levels"]]
    height, radius = record["height_m"], record["crown_radius_m"]
    return {"names": lod_group_names(record["id"], len(switch)), "levels": [lv["name"] for lv in record["levels"]],
            "unity_transition": unity_transitions(switch, height, radius),
            "unreal_screen_size": unreal_screen_sizes(switch, height, radius)}


def lod_group_thresholds(entry: dict) -> list[float]:
    """The FBX LodGroup node's thresholds, one per switch: the Unity transitions as percentages of the screen
    height (the node says its thresholds are percentages; an engine reading distances would misread them)."""
    return [round(100.0 * t, 4) for t in entry["unity_transition"][:-1]]


def write_lod_group_node(location, relative: str, ident: str, entry: dict) -> int:
    """Rewrite the LOD-group FBX at `relative` in the library `location` (as Blender wrote it) with its LodGroup
    node `ident` holding the levels `entry["names"]` in order (`Location.write_atomic`: whole files only).
    Returns the file's new size in bytes."""
    data = add_lod_group_node(location.read_bytes(relative), ident, entry["names"], lod_group_thresholds(entry))
    location.write_atomic(relative, data)
    return len(data)
