"""The skeletal wind pieces of the asset GLB: a level's joint nodes and skin, skin attributes on a primitive,
and the looping `wind` animation that turns every level's joints (one sampler per joint, shared by the levels)
and leans the impostor whole.

In: a GlbWriter, the asset's WindRig and WindClip (Z up). Out: glTF entries (Y up); the layout is
`farm.library.gltf_asset`'s.
"""
from __future__ import annotations

import numpy as np

from species.meshing.gltf import ARRAY_BUFFER, Z_UP_TO_Y_UP, GlbWriter, z_up_to_y_up

__all__ = ["WIND_ANIMATION", "joint_nodes", "skin_entry", "add_skin_attributes", "wind_animation",
           "y_up_quaternions"]

WIND_ANIMATION = "wind"


def y_up_quaternions(quaternions: np.ndarray) -> np.ndarray:
    """(..., 4) float32 quaternions (x, y, z, w) of Z-up rotations as glTF's Y-up frame sees them (the vector
    part turns like any vector)."""
    q = np.asarray(quaternions, np.float64)
    vector = q[..., :3] @ Z_UP_TO_Y_UP.T
    return np.concatenate([vector, q[..., 3:]], axis=-1).astype(np.float32)


def joint_nodes(writer: GlbWriter, rig, prefix: str) -> list[int]:
    """Node indices of the rig's joints (rig order), named `<prefix>_<joint>` (the same names in every level, so
    each level's armature has the same bones), each at its rest offset from its parent, children linked; the
    first is the hierarchy's root."""
    offsets = z_up_to_y_up(rig.local_translation).astype(np.float64)
    nodes = [writer.node({"name": f"{prefix}_{name}", "translation": [float(v) for v in offset]})
             for name, offset in zip(rig.names, offsets)]
    for j, parent in enumerate(rig.parent):
        if parent >= 0:
            writer.nodes[nodes[parent]].setdefault("children", []).append(nodes[j])
    return nodes


def skin_entry(writer: GlbWriter, rig, joints: list[int], name: str) -> dict:
    """A glTF skin over `joints` (rig order) with inverse bind matrices: each joint rests unrotated at its pivot."""
    inverse_bind = np.tile(np.eye(4, dtype=np.float32), (rig.n_joints, 1, 1))
    inverse_bind[:, :3, 3] = -z_up_to_y_up(rig.position)
    column_major = np.ascontiguousarray(inverse_bind.transpose(0, 2, 1)).reshape(rig.n_joints, 16)
    return {"name": name, "joints": joints, "skeleton": joints[0],
            "inverseBindMatrices": writer.floats(column_major, "MAT4", None)}


def add_skin_attributes(writer: GlbWriter, primitive: dict, joints: np.ndarray, weights: np.ndarray) -> dict:
    """The primitive with JOINTS_0 (unsigned short) and WEIGHTS_0 (float) of (V, 4) joints and weights."""
    primitive["attributes"]["JOINTS_0"] = writer.buffer.accessor(
        np.ascontiguousarray(joints, np.uint16), "VEC4", ARRAY_BUFFER)
    primitive["attributes"]["WEIGHTS_0"] = writer.floats(weights, "VEC4")
    return primitive


def wind_animation(writer: GlbWriter, clip, level_joints: list[list[int]], impostor_node: int | None) -> dict:
    """The `wind` animation: each joint's local rotation keyed over the clip (linear), one sampler per joint
    shared by every level's copy of it; `impostor_node` (a node above the impostor card) leans with the tree."""
    times = writer.floats(clip.times.astype(np.float32), "SCALAR", None, with_bounds=True)
    rotations = y_up_quaternions(clip.rotations)
    samplers = [{"input": times, "output": writer.floats(rotations[:, j], "VEC4", None), "interpolation": "LINEAR"}
                for j in range(rotations.shape[1])]
    channels = [{"sampler": j, "target": {"node": node, "path": "rotation"}}
                for nodes in level_joints for j, node in enumerate(nodes)]
    if impostor_node is not None:
        samplers.append({"input": times, "output": writer.floats(y_up_quaternions(clip.impostor), "VEC4", None),
                         "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": impostor_node, "path": "rotation"}})
    return {"name": WIND_ANIMATION, "samplers": samplers, "channels": channels,
            "extras": {"period_s": clip.duration, "loops": True}}
