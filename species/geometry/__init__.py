"""Geometry over plain arrays shared by every generator: rotations, curve frames, polyline simplification,
pipe-model radii, faces split among crossed planes, tree topology (depths, depth-by-depth sweeps), unit vectors
and a mesh's tangent frames for normal maps.
"""
from __future__ import annotations

from .rotations import (apply, declination, euler_xyz, from_euler_xyz, premul, rot_axis, rot_x, rot_y, rot_z,
    tilt_frames, track_frames, unit_quaternions, zxz)
from .frames import FrameError, parallel_transport_frames, polyline_tangents, rotation_minimizing_frames
from .polyline_simplify import simplification_keys
from .radii import pipe_model_radii
from .sectors import plane_sectors
from .tangents import DEGENERATE_UV_SINE, vertex_tangents
from .topology import depth_levels, node_depths
from .vectors import MIN_LENGTH, column_bounds, dot3, row_bounds, unit_vectors, unit_vectors_and_lengths

__all__ = [
    "rot_x", "rot_y", "rot_z", "rot_axis", "premul", "track_frames", "tilt_frames", "zxz", "declination", "apply",
    "euler_xyz", "from_euler_xyz", "FrameError", "polyline_tangents", "parallel_transport_frames",
    "rotation_minimizing_frames", "simplification_keys", "pipe_model_radii", "node_depths",
    "depth_levels", "plane_sectors", "unit_vectors", "unit_vectors_and_lengths", "column_bounds", "row_bounds",
    "dot3", "MIN_LENGTH", "vertex_tangents", "DEGENERATE_UV_SINE", "unit_quaternions",
]
