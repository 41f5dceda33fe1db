"""Tree to L-string (thesis 003 Algorithm 4) and L-string to tree with noise (Algorithm 6), in our Z-up world.

In: a Skeleton and a node, or an L-string and an rng. Out: the bracketed L-string, or a new Skeleton (root at 0).

Angles are absolute world angles that the parser assigns, not relative turns (digest 3.6-3.7, 3.10). The
thesis works Y up; our frame maps to its frame by the rotation (x, y, z)_thesis = (x, z, -y)_ours (+90 degrees
about x, the same rotation glTF export uses), so its formulas become, for a unit edge direction d:
    yaw   = atan2(-d.y, d.x)                 (thesis atan2(d.z, d.x))
    pitch = atan2(d.z, hypot(d.x, d.y))      (thesis atan2(d.y, hypot(d.x, d.z))), the elevation
    d     = (cos p cos y, -cos p sin y, sin p)   (thesis (cos p cos y, sin p, cos p sin y))
A string written from a Y-up tree by the thesis code is therefore the string we write from the same tree
turned Z up. Unlike the thesis, both angles are always written (a zero angle is '+(0.000)' / '&(0.000)'),
because an omitted setter would leave the previous absolute value in force and break the round trip.
Numbers have 3 decimals; lengths are metres.
"""
from __future__ import annotations

import re

import numpy as np

from ..errors import TreefarmError
from ..geometry.radii import pipe_model_radii
from ..geometry.topology import depth_levels, node_depths
from ..skeleton import Skeleton

__all__ = ["LStringError", "tree_to_lstring", "lstring_to_tree", "lstring_round_trip", "edge_angles", "branch_orders"]


class LStringError(TreefarmError):
    """An L-string Algorithm 6 cannot read; the message quotes the offending text."""


def edge_angles(vectors: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Yaw and pitch in degrees and length in metres of (E, 3) edge vectors (formulas in the module doc)."""
    vectors = np.asarray(vectors, np.float64)
    length = np.linalg.norm(vectors, axis=1)
    yaw = np.degrees(np.arctan2(-vectors[:, 1], vectors[:, 0]))
    pitch = np.degrees(np.arctan2(vectors[:, 2], np.hypot(vectors[:, 0], vectors[:, 1])))
    return yaw, pitch, length


def _setter(positive: str, negative: str, values: np.ndarray) -> list[str]:
    # abs() also turns -0.0 into 0.0, so a zero angle always prints as '+(0.000)'.
    return [f"{positive}({abs(v):.3f})" if v >= 0 else f"{negative}({-v:.3f})" for v in values.tolist()]


def tree_to_lstring(skeleton: Skeleton, node: int = 0) -> str:
    """Algorithm 4: the bracketed L-string of the subtree under `node`, one '[+(yaw)&(pitch)F(len)...]' per edge.

    Children are written in index order; the walk is iterative, so deep trees do not hit Python's recursion limit.
    """
    if not 0 <= node < len(skeleton):
        raise LStringError(f"node {node} is not in the skeleton (nodes 0..{len(skeleton) - 1})")
    parent = skeleton.parent
    yaw, pitch, length = edge_angles(skeleton.positions[1:].astype(np.float64)
                                     - skeleton.positions[parent[1:]].astype(np.float64))
    edge_text = [""] + [a + b + f"F({d:.3f})" for a, b, d in zip(_setter("+", "-", yaw), _setter("&", "^", pitch),
                                                                  length.tolist())]
    parts: list[str] = []
    open_nodes = [node]
    stack = list(skeleton.children(node)[::-1])
    while stack:
        child = int(stack.pop())
        while open_nodes[-1] != parent[child]:  # close the subtrees this child is not inside
            open_nodes.pop()
            parts.append("]")
        parts.append("[" + edge_text[child])
        open_nodes.append(child)
        stack.extend(skeleton.children(child)[::-1].tolist())
    parts.append("]" * (len(open_nodes) - 1))
    return "".join(parts)


_TOKEN = re.compile(r"\s*(?:([Ff])(?:\(([^()]*)\))?|([-+&^])(?:\(([^()]*)\))?|(\[)|(\])|([A-Za-z]))")


def _number(text: str | None, symbol: str, position: int, lstring: str) -> float:
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise LStringError(f"{symbol!r} at position {position} needs a number in parentheses, got {text!r} "
                           f"in {lstring[max(0, position - 20):position + 20]!r}") from None
    if not np.isfinite(value):
        raise LStringError(f"{symbol!r} at position {position} has a non-finite value {text!r}")
    return value


def _parse(lstring: str, default_length: float):
    """Sequential read of the string: per F its parent F (-1 = root), absolute yaw and pitch, distance."""
    parent, yaws, pitches, dists = [], [], [], []
    current, yaw, pitch, dist = -1, 0.0, 0.0, default_length
    stack = []
    position = 0
    while position < len(lstring):
        match = _TOKEN.match(lstring, position)
        if match is None:
            if lstring[position:].strip() == "":
                break
            raise LStringError(f"unexpected {lstring[position]!r} at position {position} in "
                               f"{lstring[max(0, position - 20):position + 20]!r}")
        forward, forward_arg, setter, setter_arg, push, pop, _ = match.groups()
        if forward:
            if forward_arg is not None:
                dist = _number(forward_arg, forward, match.start(1), lstring)
            parent.append(current)
            yaws.append(yaw)
            pitches.append(pitch)
            dists.append(dist)
            current = len(parent) - 1
        elif setter:
            value = _number(setter_arg, setter, match.start(3), lstring)
            if setter in "+-":
                yaw = value if setter == "+" else -value
            else:
                pitch = value if setter == "&" else -value
        elif push:
            stack.append((current, yaw, pitch))
        elif pop:
            if not stack:
                raise LStringError(f"']' at position {match.start(6)} closes no '['")
            current, yaw, pitch = stack.pop()
        position = match.end()
    if stack:
        raise LStringError(f"{len(stack)} unclosed '[' in the L-string")
    return (np.array(parent, np.int64), np.array(yaws, np.float64), np.array(pitches, np.float64),
            np.array(dists, np.float64))


def branch_orders(positions: np.ndarray, parent: np.ndarray) -> np.ndarray:
    """(N,) uint8 branch orders: at each node the straightest child continues the branch, the others add 1.

    At the root the most upward child continues. For trees rebuilt from L-strings, which carry no orders.
    """
    n = len(parent)
    child = np.arange(1, n)
    edge = positions[child] - positions[parent[child]]
    edge = edge / np.maximum(np.linalg.norm(edge, axis=1, keepdims=True), 1e-12)
    incoming = np.zeros((n, 3))
    incoming[0] = (0.0, 0.0, 1.0)
    incoming[child] = edge
    straightness = np.einsum("ij,ij->i", edge, incoming[parent[child]])
    keys = np.lexsort((child, -straightness, parent[child]))
    first = np.ones(len(keys), bool)
    first[1:] = parent[child][keys][1:] != parent[child][keys][:-1]
    step = np.ones(n, np.int64)
    step[0] = 0
    step[child[keys][first]] = 0
    order = step.copy()
    for idx in depth_levels(node_depths(parent)):
        order[idx] += order[parent[idx]]
    return np.minimum(order, 255).astype(np.uint8)


def lstring_to_tree(lstring: str, rng: np.random.Generator, degree_diff: float = 10.0,
                    dist_diff_percent: float = 0.15, tip_radius: float = 0.004, pipe_exponent: float = 2.5,
                    default_length: float = 0.1) -> Skeleton:
    """Algorithm 6: rebuild a subtree from an L-string, each F jittered, root at the origin.

    degree_diff : degrees; every F's yaw and pitch each get U(-degree_diff, degree_diff) added (digest default 10).
    dist_diff_percent : every F's length is scaled by U(1 - p, 1 + p) (digest default 0.15); 0 and 0 rebuild
    the tree exactly (to the string's 3 decimals). A bare F reuses the last distance (default_length metres
    before any). Radii follow the pipe model from `tip_radius`; orders come from `branch_orders`.
    """
    _check_noise(degree_diff, dist_diff_percent)
    move_parent, yaw, pitch, dist = _parse(lstring, default_length)
    if len(move_parent) == 0:
        raise LStringError(f"the L-string {lstring[:40]!r} has no F: nothing to build")
    return _noisy_tree(move_parent, yaw, pitch, dist, rng, degree_diff, dist_diff_percent, tip_radius, pipe_exponent)


def lstring_round_trip(skeleton: Skeleton, rng: np.random.Generator, degree_diff: float = 10.0,
                       dist_diff_percent: float = 0.15, tip_radius: float = 0.004, pipe_exponent: float = 2.5,
                       node: int = 0) -> Skeleton:
    """`lstring_to_tree(tree_to_lstring(skeleton, node), rng, ...)` without writing and parsing the text: the
    same moves (each number rounded as the string writes it), the same draws from `rng`, the same Skeleton."""
    _check_noise(degree_diff, dist_diff_percent)
    if not 0 <= node < len(skeleton):
        raise LStringError(f"node {node} is not in the skeleton (nodes 0..{len(skeleton) - 1})")
    parent = skeleton.parent
    move_of = {node: -1}
    visited: list[int] = []
    stack = skeleton.children(node)[::-1].tolist()
    while stack:  # the string's order: depth first, children in index order
        child = stack.pop()
        move_of[child] = len(visited)
        visited.append(child)
        stack.extend(skeleton.children(child)[::-1].tolist())
    if not visited:
        raise LStringError(f"node {node} has no child: its L-string has no F, nothing to build")
    visited = np.array(visited, np.int64)
    yaw, pitch, length = edge_angles(skeleton.positions[visited].astype(np.float64)
                                     - skeleton.positions[parent[visited]].astype(np.float64))
    move_parent = np.array([move_of[int(p)] for p in parent[visited]], np.int64)
    return _noisy_tree(move_parent, _as_written(yaw), _as_written(pitch), _as_written(length), rng, degree_diff,
                       dist_diff_percent, tip_radius, pipe_exponent)


def _as_written(values: np.ndarray) -> np.ndarray:
    """Values as `tree_to_lstring` writes them (3 decimals, the sign in the symbol) and `_parse` reads them back:
    thousandths rounded to the nearest integer and divided by 1000 is the float of the decimal text, except
    within rounding error of a half, where the text itself is written and read."""
    if not np.isfinite(values).all():
        raise LStringError(f"a non-finite value {values[~np.isfinite(values)][0]} in the tree's edges")
    thousandths = np.abs(values) * 1000.0
    magnitude = np.rint(thousandths) / 1000.0
    near_half = np.flatnonzero(np.abs(thousandths - np.floor(thousandths) - 0.5) < _NEAR_HALF)
    magnitude[near_half] = [float(f"{v:.3f}") for v in np.abs(values[near_half]).tolist()]
    return np.where(values >= 0, magnitude, -magnitude)


# Thousandths this close to a half may round either way in float arithmetic (the product's own error is orders
# of magnitude smaller for any length or angle of a tree); the exact decimal rounding decides them.
_NEAR_HALF = 1e-6


def _check_noise(degree_diff: float, dist_diff_percent: float) -> None:
    if not 0 <= degree_diff <= 180:
        raise LStringError(f"degree_diff = {degree_diff}: allowed degrees in [0, 180]")
    if not 0 <= dist_diff_percent < 1:
        raise LStringError(f"dist_diff_percent = {dist_diff_percent}: allowed a fraction in [0, 1)")


def _noisy_tree(move_parent: np.ndarray, yaw: np.ndarray, pitch: np.ndarray, dist: np.ndarray,
                rng: np.random.Generator, degree_diff: float, dist_diff_percent: float, tip_radius: float,
                pipe_exponent: float) -> Skeleton:
    """Algorithm 6's build from the moves (per F its parent F, -1 the root, absolute yaw and pitch, distance)."""
    count = len(move_parent)
    dist = dist * rng.uniform(1 - dist_diff_percent, 1 + dist_diff_percent, count)
    yaw_rad = np.radians(yaw + rng.uniform(-degree_diff, degree_diff, count))
    pitch_rad = np.radians(pitch + rng.uniform(-degree_diff, degree_diff, count))
    offsets = np.stack([np.cos(pitch_rad) * np.cos(yaw_rad), -np.cos(pitch_rad) * np.sin(yaw_rad),
                        np.sin(pitch_rad)], axis=1) * dist[:, None]

    parent = np.concatenate(([-1], move_parent + 1))  # node 0 is the root; F k is node k + 1
    positions = np.zeros((count + 1, 3))
    positions[1:] = offsets
    for idx in depth_levels(node_depths(parent), first=2):  # level 1 hangs from the root at the origin
        positions[idx] += positions[parent[idx]]
    return Skeleton(positions=positions, parent=parent, radius=pipe_model_radii(parent, tip_radius, pipe_exponent),
                    order=branch_orders(positions, parent))
