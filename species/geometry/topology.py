"""Tree topology over parent arrays: node depths and the depth-by-depth sweeps every generator runs.

In: (N,) int parent arrays (-1 at a root). Out: (N,) depths, and node indices grouped by depth, so a sweep from
the root (or from the tips) is one vectorized step per depth level instead of a loop over nodes.
"""
from __future__ import annotations

from typing import Iterator

import numpy as np

__all__ = ["node_depths", "depth_levels"]


def node_depths(parent: np.ndarray) -> np.ndarray:
    """(N,) int32, edges from the root, for a parent array of a forest (-1 at each root).

    Pointer jumping (each pass doubles the hop length) keeps this vectorized: O(N log depth).
    """
    parent = np.asarray(parent, np.int64)
    ancestor = np.where(parent < 0, np.arange(len(parent)), parent)
    hops = (parent >= 0).astype(np.int64)
    while True:
        next_ancestor = ancestor[ancestor]
        moved = next_ancestor != ancestor
        if not moved.any():
            return hops.astype(np.int32)
        hops = hops + np.where(moved, hops[ancestor], 0)
        ancestor = next_ancestor


def depth_levels(depth: np.ndarray, first: int = 1, tips_first: bool = False) -> Iterator[np.ndarray]:
    """The node indices of each depth from `first` to the deepest (in index order within a level); with
    `tips_first`, from the deepest up to `first`. A sweep sets a level from its parents' finished values."""
    depth = np.asarray(depth)
    deepest = int(depth.max(initial=0))
    by_depth = np.argsort(depth, kind="stable")
    starts = np.searchsorted(depth[by_depth], np.arange(deepest + 2))
    levels = range(deepest, first - 1, -1) if tips_first else range(first, deepest + 1)
    for level in levels:
        yield by_depth[starts[level]:starts[level + 1]]
