"""Weber & Penn (1995) in the parameterisation of Blender's Sapling add-on: the dictionary schema, the
stems and leaves of each level, the crown shapes, and the presets.
"""
from __future__ import annotations

from .generator import grow, grow_validated, WeberPennTree
from .schema import REALIZED_DRAWS, SAPLING_KEYS, SCHEMA, validate
from .stems import grow_level, Level
from .leaves import leaf_transforms
from .shapes import auto_taper, SHAPE_NAMES, shape_ratio
from .presets import make_preset

__all__ = [
    "grow", "grow_validated", "WeberPennTree", "validate", "SCHEMA", "REALIZED_DRAWS", "SAPLING_KEYS", "Level",
    "grow_level", "leaf_transforms", "shape_ratio", "auto_taper", "SHAPE_NAMES", "make_preset",
]
