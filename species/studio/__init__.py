"""What a studio asset adds to a tree: levels of detail, leaf cluster cards, wind data (and its baked skeletal
clip), collision capsules and PBR textures with season variants.
"""
from __future__ import annotations

from .lod import (build_lod, card_clumps, CLUMP_ATTRIBUTE, LOD_NODE_STEPS, LOD_SIDES, LOD_SWITCH_PX,
    LodBudgetError, LodLevel, metres_per_pixel, nearest_kept_ancestor, simplify_skeleton, subtree_maximum,
    TOLERANCE_LADDER_PX, TreeLods)
from .leaf_clusters import CLUSTER_AREA_GAIN, LeafCards
from .wind import branch_phases, branch_pivots, branch_reaches, GOLDEN_RATIO_CONJUGATE, wind_attributes, WIND_LAYOUT
from .skeletal_wind import (follow_joints, skin_weights, WindClip, wind_clip, WindClipSettings, wind_rig,
    WindRig)
from .collision import BRANCH_CAPSULES, capsule_mesh, collision_capsules, MAX_BRANCHES, TRUNK_CAPSULES
from .pbr_textures import bark_maps, BarkMaps, leaf_atlas, season_leaf_colour, SEASON_LEAF_COLOURS, SEASONS

__all__ = [
    "LodLevel", "LodBudgetError", "TreeLods", "build_lod", "simplify_skeleton", "metres_per_pixel",
    "nearest_kept_ancestor", "LOD_SIDES", "LOD_NODE_STEPS", "LOD_SWITCH_PX", "TOLERANCE_LADDER_PX",
    "CLUMP_ATTRIBUTE", "card_clumps", "subtree_maximum", "LeafCards", "CLUSTER_AREA_GAIN", "WIND_LAYOUT",
    "branch_pivots", "branch_phases", "branch_reaches", "wind_attributes", "WindClipSettings", "WindRig",
    "WindClip", "wind_rig", "wind_clip", "skin_weights", "follow_joints", "GOLDEN_RATIO_CONJUGATE", "collision_capsules",
    "capsule_mesh", "TRUNK_CAPSULES", "BRANCH_CAPSULES", "MAX_BRANCHES", "BarkMaps", "bark_maps", "leaf_atlas",
    "SEASON_LEAF_COLOURS", "SEASONS", "season_leaf_colour",
]
