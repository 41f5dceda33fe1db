"""Self-organizing growth by space colonization (Palubicki et al. 2009, seed 003): the generator, its
parameter schema, growth spaces, resource allocation, the shadow grid, steering, and the presets.
"""
from __future__ import annotations

from .generator import (bole_guide, Colonizer, crown_space, grow, grow_in_space, REFERENCE_INTERNODE,
    seed_from_guide)
from .params import at_iteration, CROWN_SHAPES, Field, SCHEDULABLE, SCHEMA, validate
from .growth_space import (DepthMapCrown, GrowthSpace, GrowthSpaceError, MeshSpace, PointSpace, profile_crown,
    PROFILE_SHAPES, ProfileCrown, random_lobes, SuperquadricLobe, UnionSpace, VoxelSpace)
from .allocation import allocate, jump_tables, OMEGA_MAX, OMEGA_MIN, path_products, priority_weights, subtree_sums
from .shadow import ShadowGrid
from .steering import hermite_curve, MarkerSteering, revolved_field, stroke_tube

__all__ = [
    "grow", "grow_in_space", "crown_space", "Colonizer", "bole_guide", "seed_from_guide", "REFERENCE_INTERNODE",
    "Field", "SCHEMA", "SCHEDULABLE",
    "validate", "at_iteration", "CROWN_SHAPES", "GrowthSpaceError", "GrowthSpace", "ProfileCrown",
    "SuperquadricLobe", "UnionSpace", "MeshSpace", "VoxelSpace", "PointSpace", "DepthMapCrown", "random_lobes",
    "PROFILE_SHAPES", "profile_crown", "jump_tables", "subtree_sums", "path_products", "allocate",
    "priority_weights", "OMEGA_MAX", "OMEGA_MIN", "ShadowGrid", "MarkerSteering", "revolved_field", "hermite_curve",
    "stroke_tube",
]
