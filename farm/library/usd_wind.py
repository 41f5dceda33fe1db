"""The skeletal wind pieces of the asset USD: a UsdSkel Skeleton with its SkelAnimation (the looping clip) shared by
every level, skin primvars on a mesh, the leaves' per-joint transforms and the impostor's lean, all time-sampled
at the clip's keys (time codes per second = SAMPLES_PER_SECOND).

In: a Usd.Stage, the asset's WindRig and WindClip (Z up, metres). Out: prims on the stage; the layout is
`farm.library.usd_asset`'s.
"""
from __future__ import annotations

import numpy as np

from species.geometry import unit_quaternions
from species.studio.skeletal_wind import SAMPLES_PER_SECOND, joint_world_poses

__all__ = ["joint_paths", "define_skeleton", "bind_skin", "joint_xforms", "lean_whole", "set_clip_time_range"]


def joint_paths(rig) -> list[str]:
    """UsdSkel joint tokens: each joint's path of names from the root (`trunk_0/trunk_1/branch_12`)."""
    paths: list[str] = []
    for name, parent in zip(rig.names, rig.parent):
        paths.append(name if parent < 0 else f"{paths[parent]}/{name}")
    return paths


def _translations(offsets: np.ndarray) -> np.ndarray:
    """(J, 4, 4) row-vector matrices (USD's convention) of translations (J, 3)."""
    matrices = np.tile(np.eye(4), (len(offsets), 1, 1))
    matrices[:, 3, :3] = offsets
    return matrices


def set_clip_time_range(stage, clip) -> None:
    """The stage's time codes run over the clip: one code per key."""
    stage.SetTimeCodesPerSecond(SAMPLES_PER_SECOND)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(len(clip.times) - 1)


def define_skeleton(stage, path: str, rig, clip):
    """A Skeleton at `path` (rest pose: unrotated joints at their pivots) and its SkelAnimation `path/wind`
    (local rotations keyed at the clip's time codes, constant translations); returns the Skeleton."""
    from pxr import UsdSkel, Vt

    skeleton = UsdSkel.Skeleton.Define(stage, path)
    joints = Vt.TokenArray(joint_paths(rig))
    skeleton.CreateJointsAttr(joints)
    skeleton.CreateJointNamesAttr(Vt.TokenArray(list(rig.names)))
    skeleton.CreateBindTransformsAttr(Vt.Matrix4dArray.FromNumpy(_translations(rig.position)))
    skeleton.CreateRestTransformsAttr(Vt.Matrix4dArray.FromNumpy(_translations(rig.local_translation)))
    animation = UsdSkel.Animation.Define(stage, f"{path}/wind")
    animation.CreateJointsAttr(joints)
    animation.CreateTranslationsAttr(Vt.Vec3fArray.FromNumpy(rig.local_translation.astype(np.float32)))
    animation.CreateScalesAttr(Vt.Vec3hArray.FromNumpy(np.ones((rig.n_joints, 3), np.float16)))
    rotations = animation.CreateRotationsAttr()
    for code, keys in enumerate(clip.rotations.astype(np.float32)):
        rotations.Set(Vt.QuatfArray.FromNumpy(np.ascontiguousarray(keys)), code)  # x, y, z, w: imaginary first
    UsdSkel.BindingAPI.Apply(skeleton.GetPrim()).CreateAnimationSourceRel().SetTargets([animation.GetPath()])
    return skeleton


def bind_skin(mesh, skeleton, joints: np.ndarray, weights: np.ndarray) -> None:
    """Skin a mesh to `skeleton`: (V, 4) joint indices and weights as vertex primvars of element size 4."""
    from pxr import Gf, UsdSkel, Vt

    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skeleton.GetPath()])
    binding.CreateJointIndicesPrimvar(False, joints.shape[1]).Set(
        Vt.IntArray.FromNumpy(np.ascontiguousarray(joints, np.int32).reshape(-1)))
    binding.CreateJointWeightsPrimvar(False, weights.shape[1]).Set(
        Vt.FloatArray.FromNumpy(np.ascontiguousarray(weights, np.float32).reshape(-1)))
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))


def joint_xforms(stage, path: str, rig, clip, chosen: np.ndarray) -> dict[int, str]:
    """An Xform per chosen joint under `path`, moving as the joint does (translate and orient keyed at the
    clip's time codes); what sits under it is placed from the joint's rest pivot. Returns {joint: prim path}."""
    from pxr import Gf, Sdf, UsdGeom

    world, position = joint_world_poses(rig, clip.rotations)
    out, ops = {}, []
    for joint in (int(j) for j in chosen):  # one prim per joint that holds leaves: at most the joint budget
        xform = UsdGeom.Xform.Define(stage, f"{path}/{rig.names[joint]}")
        ops.append((joint, xform.AddTranslateOp().GetAttr(), xform.AddOrientOp().GetAttr()))
        out[joint] = str(xform.GetPath())
    with Sdf.ChangeBlock():  # thousands of samples: notices once, not per sample
        for joint, translate, orient in ops:
            quaternions = unit_quaternions(world[:, joint]).tolist()
            for code, ((x, y, z, w), offset) in enumerate(zip(quaternions, position[:, joint].tolist())):
                translate.Set(Gf.Vec3d(*offset), code)
                orient.Set(Gf.Quatf(w, x, y, z), code)
    return out


def lean_whole(prim, clip) -> None:
    """The prim turns about its origin (the tree's base) with the clip's whole-tree lean."""
    from pxr import Gf, UsdGeom

    orient = UsdGeom.Xformable(prim).AddOrientOp()
    for code, (x, y, z, w) in enumerate(clip.impostor):
        orient.Set(Gf.Quatf(float(w), float(x), float(y), float(z)), code)

