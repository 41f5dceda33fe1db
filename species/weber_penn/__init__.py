"""Weber & Penn (1995) in the parameterisation of Blender's Sapling add-on: the dictionary schema and the
parameter object read from it, the stems and leaves of each level, the crown shapes, assembly into a Skeleton,
the presets, what Sapling's keys mean (`sapling_keys`: `draws: ranges` or `realized`) and Sapling's own preset
files (`sapling_preset`).
"""
from __future__ import annotations

from .generator import grow, grow_tree, grow_validated
from .schema import REALIZED_DRAWS, SAPLING_KEYS, SCHEMA, validate
from .params import LeafParams, PruneParams, RealizedDraws, SaplingRanges, StemLevelParams, WeberPennParams
from .sapling_keys import (BLENDER_ONLY_KEYS, DRAWS, OLD_SAPLING_KEYS, draws_reading, draws_semantics, ignored_keys,
                           reads_as_sapling_preset)
from .sapling_preset import SaplingPreset, load_sapling_preset, read_sapling_preset, sapling_preset_from_settings
from .stems import grow_level, Level, MAX_STEMS_PER_LEVEL
from .stem_directions import (attract_up, bent_direction, branch_turn, crown_taper, sapling_split_angles,
                              segment_frames, split_angle, spread_angle, world_directions)
from .child_points import child_points, ChildPoints
from .leaves import leaf_transforms
from .assembly import assemble, MIN_RADIUS, node_key, SkeletonAssemblyError, WeberPennTree
from .shapes import auto_taper, SHAPE_NAMES, shape_ratio
from .size_estimate import (check_tree_size, estimate_size, MAX_ESTIMATED_LEAVES, MAX_ESTIMATED_NODES,
                            MAX_ESTIMATED_STEMS_PER_LEVEL, SizeEstimate)
from .presets import make_preset

__all__ = [
    "grow", "grow_tree", "grow_validated", "validate", "SCHEMA", "REALIZED_DRAWS", "SAPLING_KEYS",
    "WeberPennParams", "StemLevelParams", "LeafParams", "PruneParams", "RealizedDraws", "SaplingRanges",
    "read_sapling_preset", "load_sapling_preset", "sapling_preset_from_settings", "SaplingPreset",
    "draws_semantics", "draws_reading", "reads_as_sapling_preset", "ignored_keys",
    "BLENDER_ONLY_KEYS", "OLD_SAPLING_KEYS", "DRAWS",
    "Level", "grow_level", "MAX_STEMS_PER_LEVEL",
    "attract_up", "bent_direction", "world_directions", "split_angle", "spread_angle", "sapling_split_angles",
    "branch_turn",
    "segment_frames", "crown_taper",
    "ChildPoints", "child_points", "leaf_transforms",
    "WeberPennTree", "assemble", "node_key", "SkeletonAssemblyError", "MIN_RADIUS",
    "shape_ratio", "auto_taper", "SHAPE_NAMES", "make_preset",
    "SizeEstimate", "estimate_size", "check_tree_size", "MAX_ESTIMATED_STEMS_PER_LEVEL", "MAX_ESTIMATED_NODES",
    "MAX_ESTIMATED_LEAVES",
]
