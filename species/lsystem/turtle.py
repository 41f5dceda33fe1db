"""The 3D turtle: turns an L-system module list into nodes, parents, widths, branch orders and frames.

In: modules [(symbol, params), ...] and the drawing settings. Out: a `TurtlePath` (arrays, Z up, metres).

Relative turtle semantics of thesis Table 2.1 (digest 3.10). The turtle frame is three unit columns
[H L U] (heading, left, up) with H x L = U; it starts at the origin with H = +Z, L = +Y, U = -X.
  F(x)  move x*step metres, adding a node      f(x)  move x*step metres without a node (see below)
  +(a)  turn left:  H toward L by a degrees     -(a)  turn right: H toward -L
  &(a)  pitch up:   H toward U                  ^(a)  pitch down: H toward -U
  \\(a) roll left:  L toward U about H          /(a)  roll right: L toward -U
  |     turn around (180 degrees about U)       !(x)  scale the width by x (bare !: by width_ratio)
  [ ]   push / pop position, frame, width       L(x)  a leaf of x times the leaf size here
Bare turns use `angle`. After each move the heading bends toward the tropism vector t by |H x t| radians
(ABOP section 2.2). A skeleton is one connected tree, so `f` moves the turtle and the next F's node
joins the last node drawn. Every other symbol (X, A, ...) is ignored.
"""
from __future__ import annotations

from dataclasses import dataclass
from itertools import chain

import numpy as np

from .rewrite import Module
from ..geometry.topology import depth_levels, node_depths

__all__ = ["TurtlePath", "interpret", "initial_frame", "turn_matrices", "leaf_cards"]


def initial_frame() -> np.ndarray:
    """(3, 3) float64, the start frame: columns H = +Z, L = +Y, U = H x L = -X."""
    return np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])


@dataclass(frozen=True)
class TurtlePath:
    """What the turtle drew. Node 0 is the start point; the others are the ends of F moves, in string order.

    positions   : (N, 3) float64, metres, Z up.
    parent      : (N,) int32, -1 for node 0; parent[i] < i.
    width       : (N,) float64, metres, the turtle width (a diameter) while drawing the move to each node;
                  node 0 takes the widest move leaving it.
    order       : (N,) uint8, branch order: +1 for the first move after a '[' (0 = the axis drawn first).
    frames      : (N, 3, 3) float64, the turtle frame [H L U] (columns) while drawing the move to each node.
    leaf_node   : (K,) int32, the node each `L` symbol hangs from (the last node drawn before it).
    leaf_frames : (K, 3, 3) float64, the turtle frame at each `L`.
    leaf_scale  : (K,) float64, each `L`'s size factor.
    """

    positions: np.ndarray
    parent: np.ndarray
    width: np.ndarray
    order: np.ndarray
    frames: np.ndarray
    leaf_node: np.ndarray
    leaf_frames: np.ndarray
    leaf_scale: np.ndarray

    @property
    def tips(self) -> np.ndarray:
        """(T,) int64, nodes without children."""
        has_child = np.zeros(len(self.parent), bool)
        has_child[self.parent[1:]] = True
        return np.flatnonzero(~has_child)


# Turn symbols: (plane code, sign). Plane 0 mixes H and L (about U), 1 mixes H and U (about L), 2 mixes L and U.
_TURNS = {"+": (0, 1.0), "-": (0, -1.0), "&": (1, 1.0), "^": (1, -1.0), "\\": (2, 1.0), "/": (2, -1.0)}
_PLANES = np.array([[0, 1], [0, 2], [1, 2]])


def turn_matrices(plane: np.ndarray, radians: np.ndarray) -> np.ndarray:
    """(T, 3, 3) float64 rotations in the turtle's own axes: frame' = frame @ R turns column a toward b."""
    plane = np.asarray(plane, np.int64)
    radians = np.asarray(radians, np.float64)
    a, b = _PLANES[plane, 0], _PLANES[plane, 1]
    cos, sin = np.cos(radians), np.sin(radians)
    rows = np.arange(len(plane))
    out = np.tile(np.eye(3), (len(plane), 1, 1))
    out[rows, a, a] = cos
    out[rows, b, b] = cos
    out[rows, b, a] = sin
    out[rows, a, b] = -sin
    return out


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis with broadcasting (np.cross's checks and moves cost more than the
    product on the few vectors of each call in this loop)."""
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def _bend(frames: np.ndarray, tropism: np.ndarray) -> np.ndarray:
    """Rotate each frame about the world axis H x t by |H x t| radians: ABOP tropism, vectorized (Rodrigues)."""
    axis = _cross(frames[:, :, 0], tropism)
    angle = np.sqrt(np.einsum("ti,ti->t", axis, axis))
    k = axis / np.maximum(angle, 1e-300)[:, None]
    cos, sin = np.cos(angle)[:, None, None], np.sin(angle)[:, None, None]
    columns = frames.transpose(0, 2, 1)  # (T, 3 columns, 3 components)
    k_dot_v = np.einsum("ti,tji->tj", k, columns)[:, :, None]
    rotated = columns * cos + _cross(k[:, None, :], columns) * sin + k[:, None, :] * k_dot_v * (1 - cos)
    return rotated.transpose(0, 2, 1)


def _scan(modules: list[Module], angle: float, width: float, width_ratio: float):
    """Pass 1 (sequential, cheap): moves, their parent moves, turns pending before each move, widths, orders."""
    move_parent, move_turns, move_length, move_drawn, move_width, move_order = [], [], [], [], [], []
    leaf_move, leaf_turns, leaf_scale = [], [], []
    turn_plane, turn_angle, turn_jitters = [], [], []
    move, pending, state_width, order, branch_pending = -1, [], width, 0, False
    move_orders = {-1: 0}
    stack = []
    for symbol, params in modules:
        if symbol == "F" or symbol == "f":
            move_parent.append(move)
            move_turns.append(pending)
            move_length.append(params[0] if params else 1.0)
            move_drawn.append(symbol == "F")
            move_width.append(state_width)
            order = move_orders[move] + 1 if branch_pending else order
            move_order.append(order)
            move = len(move_parent) - 1
            move_orders[move] = order
            pending, branch_pending = [], False
        elif symbol in _TURNS:
            plane, sign = _TURNS[symbol]
            pending.append(len(turn_plane))
            turn_plane.append(plane)
            turn_angle.append(sign * (params[0] if params else angle))
            turn_jitters.append(True)
        elif symbol == "|":
            pending.append(len(turn_plane))
            turn_plane.append(0)
            turn_angle.append(180.0)
            turn_jitters.append(False)
        elif symbol == "[":
            stack.append((move, pending, state_width, order, branch_pending))
            pending, branch_pending = list(pending), True
        elif symbol == "]":
            move, pending, state_width, order, branch_pending = stack.pop()
        elif symbol == "!":
            state_width *= params[0] if params else width_ratio
        elif symbol == "L":
            leaf_move.append(move)
            leaf_turns.append(list(pending))
            leaf_scale.append(params[0] if params else 1.0)
    moves = dict(parent=np.array(move_parent, np.int64), length=np.array(move_length, np.float64),
                 drawn=np.array(move_drawn, bool), width=np.array(move_width, np.float64),
                 order=np.array(move_order, np.int64))
    leaves = dict(move=np.array(leaf_move, np.int64), scale=np.array(leaf_scale, np.float64))
    turns = dict(plane=np.array(turn_plane, np.int64), degrees=np.array(turn_angle, np.float64),
                 jitters=np.array(turn_jitters, bool))
    return moves, leaves, turns, move_turns + leaf_turns


def _local_rotations(turn_lists: list[list[int]], turn_rotations: np.ndarray) -> np.ndarray:
    """(O, 3, 3): the product of each owner's pending turns, in order, composed one position at a time."""
    local = np.tile(np.eye(3), (len(turn_lists), 1, 1))
    counts = np.fromiter((len(t) for t in turn_lists), np.int64, len(turn_lists))
    if counts.sum() == 0:
        return local
    owner = np.repeat(np.arange(len(turn_lists)), counts)
    turn = np.fromiter(chain.from_iterable(turn_lists), np.int64, int(counts.sum()))
    position = np.arange(len(owner)) - np.repeat(np.cumsum(counts) - counts, counts)
    for k in range(int(counts.max())):
        sel = position == k
        local[owner[sel]] = local[owner[sel]] @ turn_rotations[turn[sel]]
    return local


def interpret(modules: list[Module], *, angle: float, step: float, width: float, width_ratio: float,
              rng: np.random.Generator, tropism=(0.0, 0.0, 0.0), angle_jitter: float = 0.0,
              step_jitter: float = 0.0, start_frame: np.ndarray | None = None) -> TurtlePath:
    """Draw a module list (semantics in the module docstring).

    angle, angle_jitter : degrees; each turn gets U(-angle_jitter, angle_jitter) added ('|' excepted).
    step : metres per unit of F's argument; step_jitter scales each move by U(1 - j, 1 + j).
    width : metres, the starting turtle width (diameter); width_ratio is what a bare '!' multiplies by.
    tropism : (3,) the bending vector t (its length is the susceptibility e).
    The turtle walks the string once; geometry is then built level by level of the move tree, vectorized.
    """
    moves, leaves, turns, turn_lists = _scan(modules, angle, width, width_ratio)
    n_moves = len(moves["parent"])
    degrees = turns["degrees"]
    if angle_jitter > 0 and len(degrees):
        degrees = degrees + np.where(turns["jitters"], rng.uniform(-angle_jitter, angle_jitter, len(degrees)), 0)
    lengths = moves["length"] * step
    if step_jitter > 0 and n_moves:
        lengths = lengths * rng.uniform(1 - step_jitter, 1 + step_jitter, n_moves)
    local = _local_rotations(turn_lists, turn_matrices(turns["plane"], np.radians(degrees)))

    # Move m is point m + 1; point 0 is the start. Levels of the move tree are independent of each other.
    tree_parent = np.concatenate(([-1], moves["parent"] + 1))
    frames = np.empty((n_moves + 1, 3, 3))
    frames[0] = initial_frame() if start_frame is None else start_frame
    after = frames.copy()  # frames after tropism, what the next move starts from
    points = np.zeros((n_moves + 1, 3))
    drawn = np.concatenate(([True], moves["drawn"]))
    anchor = np.arange(n_moves + 1)  # nearest drawn point at or above each point
    tropism = np.asarray(tropism, np.float64)
    bend = bool(np.any(tropism))
    for idx in depth_levels(node_depths(tree_parent)):
        par = tree_parent[idx]
        frames[idx] = after[par] @ local[idx - 1]
        points[idx] = points[par] + frames[idx, :, 0] * lengths[idx - 1, None]
        after[idx] = _bend(frames[idx], tropism) if bend else frames[idx]
        anchor[idx] = np.where(drawn[idx], idx, anchor[par])

    keep = np.flatnonzero(drawn)
    new_index = np.full(n_moves + 1, -1, np.int64)
    new_index[keep] = np.arange(len(keep))
    parent = np.full(len(keep), -1, np.int32)
    parent[1:] = new_index[anchor[tree_parent[keep[1:]]]]
    node_width = np.concatenate(([0.0], moves["width"]))[keep]
    if len(keep) > 1:
        first = np.zeros(len(keep))
        np.maximum.at(first, parent[1:], node_width[1:])
        node_width[0] = first[0]
    node_width[0] = node_width[0] if node_width[0] > 0 else width
    order = np.concatenate(([0], moves["order"]))[keep]

    leaf_point = leaves["move"] + 1
    leaf_local = local[n_moves:]
    return TurtlePath(
        positions=points[keep], parent=parent, width=node_width, order=np.minimum(order, 255).astype(np.uint8),
        frames=frames[keep], leaf_node=new_index[anchor[leaf_point]].astype(np.int32),
        leaf_frames=after[leaf_point] @ leaf_local if len(leaf_point) else np.zeros((0, 3, 3)),
        leaf_scale=leaves["scale"])


def leaf_cards(points: np.ndarray, frames: np.ndarray, length, width, tilt_degrees, roll_radians) -> np.ndarray:
    """(M, 4, 4) float32 leaf transforms: the unit card's length axis leans `tilt` from H, rolled about H.

    points : (M, 3) metres, the stems; frames : (M, 3, 3) turtle frames [H L U]; length, width : metres,
    scalars or (M,); tilt_degrees : scalar or (M,); roll_radians : (M,) or scalar, 0 leans toward L.
    Columns: x = card width axis (width), y = card normal (unit x width), z = length axis (length).
    """
    heading, left, up = frames[:, :, 0], frames[:, :, 1], frames[:, :, 2]
    tilt = np.radians(np.broadcast_to(np.asarray(tilt_degrees, np.float64), (len(points),)))[:, None]
    roll = np.broadcast_to(np.asarray(roll_radians, np.float64), (len(points),))[:, None]
    radial = np.cos(roll) * left + np.sin(roll) * up
    along = np.cos(tilt) * heading + np.sin(tilt) * radial
    side = -np.sin(roll) * left + np.cos(roll) * up
    normal = _cross(along, side)
    length = np.broadcast_to(np.asarray(length, np.float64), (len(points),))[:, None]
    width = np.broadcast_to(np.asarray(width, np.float64), (len(points),))[:, None]
    out = np.zeros((len(points), 4, 4))
    out[:, :3, 0], out[:, :3, 1], out[:, :3, 2] = side * width, normal * width, along * length
    out[:, :3, 3] = points
    out[:, 3, 3] = 1.0
    return out.astype(np.float32)
