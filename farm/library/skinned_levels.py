"""Each level of an asset skinned to its one wind rig: the bark's and twig cards' skin weights and the joint
each leaf card follows, every level on the same joints (`LibraryAsset.wind_rig`).

In: a WindRig and the asset's levels (`farm.library.asset.LevelData`). Out: one `LevelSkin` per level (None for the
impostor, which leans whole), made once per asset by `build_asset` (`LibraryAsset.level_skins`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from species.studio.skeletal_wind import follow_joints, skin_weights

__all__ = ["LevelSkin", "level_skins", "skin_of"]


@dataclass(frozen=True)
class LevelSkin:
    """bark_joints, bark_weights : (V, 4) uint8 / float32 per bark vertex (heaviest first, weights sum to 1).
    twig_joints, twig_weights : the same per twig card vertex, or None without twig cards.
    leaf_joint : (M,) int64, the joint each leaf card (instance) moves with."""

    bark_joints: np.ndarray
    bark_weights: np.ndarray
    twig_joints: np.ndarray | None
    twig_weights: np.ndarray | None
    leaf_joint: np.ndarray


def skin_of(rig, level) -> LevelSkin:
    """The skin of one level (not the impostor) on `rig`."""
    bark = level.mesh.bark
    joints, weights = skin_weights(rig, bark.vertices, level.lod0_branches(bark.attributes["branch"]))
    twig_joints = twig_weights = None
    if level.twigs is not None:  # twig cards carry LOD0 branch ids already
        twig_joints, twig_weights = skin_weights(rig, level.twigs.vertices, level.twigs.attributes["branch"])
    skeleton = level.skeleton
    if skeleton.n_leaves:
        leaf_branch = level.lod0_branches(skeleton.branch_id[skeleton.leaf_node])
        leaf_joint = follow_joints(rig, skeleton.leaves[:, :3, 3], leaf_branch)
    else:
        leaf_joint = np.zeros(0, np.int64)
    return LevelSkin(joints, weights, twig_joints, twig_weights, leaf_joint)


def level_skins(rig, levels: list) -> list[LevelSkin | None]:
    """One LevelSkin per level in order, None for the impostor; [] without a rig."""
    if rig is None:
        return []
    return [None if level.name == "IMPOSTOR" else skin_of(rig, level) for level in levels]
