"""Skeletons for tests of meshing and export: small hand-made trees and a random branching one.

Independent of any growth model, so mesh and exporter tests do not depend on a generator's output.
"""
from __future__ import annotations

import numpy as np

from species.geometry.radii import pipe_model_radii
from species.skeleton import Skeleton


def leaf_transforms(positions, length_axes, normal_axes, sizes) -> np.ndarray:
    """(M, 4, 4) float32: unit cards (width x, length z, normal y) scaled by `sizes`, stems at `positions`.

    positions, length_axes, normal_axes : (M, 3) float; sizes : (M,) float metres.
    """
    z = np.asarray(length_axes, float).reshape(-1, 3)
    z = z / np.linalg.norm(z, axis=1, keepdims=True)
    y = np.asarray(normal_axes, float).reshape(-1, 3)
    y = y - z * np.einsum("ij,ij->i", y, z)[:, None]
    y = y / np.linalg.norm(y, axis=1, keepdims=True)
    x = np.cross(y, z)
    size = np.asarray(sizes, float).reshape(-1, 1)
    out = np.zeros((len(z), 4, 4))
    out[:, :3, 0], out[:, :3, 1], out[:, :3, 2] = x * size, y * size, z * size
    out[:, :3, 3] = np.asarray(positions, float).reshape(-1, 3)
    out[:, 3, 3] = 1.0
    return out.astype(np.float32)


def straight_trunk(height: float = 2.0, base_radius: float = 0.1, n_nodes: int = 5) -> Skeleton:
    """One vertical, tapering branch from the origin to `height`, no leaves."""
    z = np.linspace(0.0, height, n_nodes)
    positions = np.stack([np.zeros_like(z), np.zeros_like(z), z], axis=1)
    radius = base_radius * np.linspace(1.0, 0.3, n_nodes)
    return Skeleton(positions, np.arange(-1, n_nodes - 1), radius, np.zeros(n_nodes))


def fork_with_leaves() -> Skeleton:
    """A bent trunk with two side branches (orders 1 and 2), a repeated node, and three leaves."""
    positions = np.array([
        [0, 0, 0], [0, 0, 1], [0.1, 0, 2], [0.1, 0, 2], [0.15, 0.05, 3],  # trunk 0-4 (3 repeats 2)
        [0.6, 0, 1.4], [1.2, 0.1, 1.9],                                   # order-1 branch from node 1
        [0.1, 0.5, 2.3],                                                  # order-1 branch from node 2
        [1.3, 0.5, 2.2], [1.4, 0.8, 2.4],                                 # order-2 twig from node 6
    ], np.float32)
    parent = np.array([-1, 0, 1, 2, 3, 1, 5, 2, 6, 8])
    radius = np.array([0.2, 0.15, 0.1, 0.1, 0.05, 0.06, 0.04, 0.03, 0.02, 0.01])
    order = np.array([0, 0, 0, 0, 0, 1, 1, 1, 2, 2])
    leaves = leaf_transforms(positions[[9, 8, 7]], [[0, 1, 0.5], [1, 0, 0], [0, 0, 1]],
                             [[0, 0, 1], [0, 0, 1], [1, 0, 0]], [0.1, 0.08, 0.12])
    return Skeleton(positions, parent, radius, order, leaves, np.array([9, 8, 7]))


def random_tree(rng: np.random.Generator, n_nodes: int = 5000, n_leaves: int = 20000,
                max_order: int = 3, height: float = 12.0) -> Skeleton:
    """A random branching tree: a wavy trunk, then branches sprouting from random nodes until `n_nodes`.

    Branches head outward and up, shorten with order, and get pipe-model radii; leaves hang from nodes of
    the two highest orders. Python loops here are per branch and run once per test session.
    """
    trunk_nodes = 40
    z = np.linspace(0.0, height, trunk_nodes)
    wobble = 0.05 * height * np.sin(z / height * 3.0)[:, None] * np.array([[1.0, 0.6]])
    positions = [np.column_stack([wobble, z])]
    parent = [np.arange(-1, trunk_nodes - 1)]
    order = [np.zeros(trunk_nodes, np.int64)]
    count = trunk_nodes
    all_positions = positions[0]
    all_order = order[0]
    while count < n_nodes:
        # Junctions: any node below the top order, away from the ground.
        eligible = np.flatnonzero((all_order < max_order) & (all_positions[:, 2] > 0.25 * height))
        junction = int(rng.choice(eligible))
        branch_order = int(all_order[junction]) + 1
        n_new = min(int(rng.integers(4, 14)) // branch_order + 2, n_nodes - count)
        step = height / 30.0 / branch_order
        heading = rng.normal(size=3)
        heading[2] = abs(heading[2]) * 0.5
        heading /= np.linalg.norm(heading)
        bends = np.cumsum(rng.normal(scale=0.15, size=(n_new, 3)), axis=0)
        directions = heading + bends
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        new_positions = all_positions[junction] + np.cumsum(directions * step, axis=0)
        new_parent = np.concatenate([[junction], np.arange(count, count + n_new - 1)])
        positions.append(new_positions)
        parent.append(new_parent)
        order.append(np.full(n_new, branch_order))
        all_positions = np.concatenate([all_positions, new_positions])
        all_order = np.concatenate([all_order, order[-1]])
        count += n_new
    parent_array = np.concatenate(parent)
    radius = pipe_model_radii(parent_array, 0.002 * height)
    leafy = np.flatnonzero(all_order >= max_order - 1)
    leaf_node = rng.choice(leafy, size=n_leaves)
    length_axes = rng.normal(size=(n_leaves, 3))
    normal_axes = rng.normal(size=(n_leaves, 3))
    sizes = rng.uniform(0.04, 0.1, size=n_leaves)
    leaves = leaf_transforms(all_positions[leaf_node], length_axes, normal_axes, sizes)
    return Skeleton(all_positions, parent_array, radius, all_order, leaves, leaf_node)
