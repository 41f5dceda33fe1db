"""Pipe-model branch radii (digest 1.7, eq. 2.7): d^n = sum of the children's d^n, from the tips to the root.

In: a parent array and the tip radius. Out: a radius per node. Growth models call it where they set no radii.
"""
from __future__ import annotations

import numpy as np

from ..errors import ParameterError
from .topology import depth_levels, node_depths

__all__ = ["pipe_model_radii"]


def pipe_model_radii(parent: np.ndarray, tip_radius, exponent: float = 2.5) -> np.ndarray:
    """Radii by the pipe model: r^n at a node is the sum of r^n over its children; tips get `tip_radius`.

    parent     : (N,) int, parent index per node, -1 for the root (node 0), parent[i] < i.
    tip_radius : float or (N,) float, metres, > 0; the radius of nodes without children (an array is
                 read only at those nodes, so tips may differ).
    exponent   : n, the pipe exponent, in [1, 4]; 2 is area-preserving (da Vinci), the farm uses 2.5.
    Returns (N,) float32 metres. A node with one child keeps its child's radius; radii never shrink
    toward the root. Computed level by level from the deepest, each level one `np.add.at`.
    """
    parent = np.asarray(parent)
    if parent.ndim != 1 or len(parent) == 0:
        raise ParameterError("parent", f"array of shape {parent.shape}", "a non-empty 1-D array of indices")
    n = len(parent)
    parent = parent.astype(np.int64)
    if parent[0] != -1 or np.any(parent[1:] < 0) or np.any(parent[1:] >= np.arange(1, n)):
        raise ParameterError("parent", "an array with parent[i] >= i or a second root",
                             "parent[0] = -1 and 0 <= parent[i] < i for i > 0")
    if not 1.0 <= float(exponent) <= 4.0:
        raise ParameterError("exponent", exponent, "a number in [1, 4]")
    tip = np.broadcast_to(np.asarray(tip_radius, np.float64), (n,))
    if not np.all(np.isfinite(tip)) or np.any(tip <= 0):
        raise ParameterError("tip_radius", float(tip.min()), "finite radii > 0 metres")

    has_child = np.zeros(n, bool)
    has_child[parent[1:]] = True
    # Work in r^n: tips start with their own value, inner nodes accumulate their children's.
    powered = np.where(has_child, 0.0, tip ** exponent)
    for nodes in depth_levels(node_depths(parent), tips_first=True):
        np.add.at(powered, parent[nodes], powered[nodes])
    return (powered ** (1.0 / exponent)).astype(np.float32)
