"""Rigid moves of drawn main branches (seed 000 ch. 4): grab a branch, move and turn it with everything growing
from it, unless the convex hulls of the moved branches would touch a branch that stays (`hull_contact`).

In: main branches as `grow.grow_model` takes them, [(polyline (K, 3) float metres, parent branch index), ...]
(-1 for the trunk), the grabbed branch's index and the move: rotation (3, 3), pivot (3,), translation (3,)
metres, p' = R (p - pivot) + pivot + t. Out: the moved branch list, or MoveRefused naming the branches in the way.
The turn a thumb swipe asks for (eq. 4.1, the touchpad of the thesis, a thumbstick here) is `swipe_angle`.
"""
from __future__ import annotations

import numpy as np

from species.errors import TreefarmError

from .hull_contact import hulls_overlap

__all__ = ["MoveRefused", "subtree_branches", "move_branches", "move_contacts", "guarded_move", "swipe_angle"]


class MoveRefused(TreefarmError):
    """A rigid move that the guard refuses: the moved branches would touch branches that stay, or a bad move."""


def subtree_branches(branches, index: int) -> list[int]:
    """The grabbed branch and every branch growing from it, directly or not, in increasing index order."""
    if not 0 <= index < len(branches):
        raise MoveRefused(f"branch {index} does not exist; allowed: 0..{len(branches) - 1}")
    parents = [int(parent) for _, parent in branches]
    inside = {index}
    grew = True
    while grew:  # a handful of drawn branches: repeat until no branch joins
        grew = False
        for child, parent in enumerate(parents):
            if parent in inside and child not in inside:
                inside.add(child)
                grew = True
    return sorted(inside)


def _rotation(rotation) -> np.ndarray:
    rotation = np.asarray(rotation, np.float64)
    if rotation.shape != (3, 3) or not np.all(np.isfinite(rotation)) \
            or not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-6) or np.linalg.det(rotation) < 0:
        raise MoveRefused("the move's rotation must be a proper 3x3 rotation matrix (orthonormal, determinant +1)")
    return rotation


def move_branches(branches, index: int, rotation=np.eye(3), pivot=(0.0, 0.0, 0.0),
                  translation=(0.0, 0.0, 0.0)) -> list:
    """The branch list with branch `index` and its subtree moved rigidly (the others as they were)."""
    rotation = _rotation(rotation)
    pivot = np.asarray(pivot, np.float64).reshape(3)
    translation = np.asarray(translation, np.float64).reshape(3)
    if not (np.all(np.isfinite(pivot)) and np.all(np.isfinite(translation))):
        raise MoveRefused("the move's pivot and translation must be finite coordinates (metres)")
    moved = set(subtree_branches(branches, index))
    out = []
    for k, (line, parent) in enumerate(branches):
        line = np.asarray(line, np.float64)
        out.append(((line - pivot) @ rotation.T + pivot + translation, parent) if k in moved else (line, parent))
    return out


def move_contacts(branches, index: int, moved_branches) -> list[tuple[int, int]]:
    """(moved branch, staying branch) pairs whose convex hulls touch after the move. The grabbed branch is
    compared with its own parent without its first sample, where it is attached."""
    moved = subtree_branches(branches, index)
    staying = [k for k in range(len(branches)) if k not in moved]
    parent = int(branches[index][1])
    contacts = []
    for m in moved:  # drawn main branches: a few dozen pairs at most
        points = np.asarray(moved_branches[m][0], np.float64)
        for s in staying:
            mine = points[1:] if (m == index and s == parent and len(points) > 1) else points
            if hulls_overlap(mine, np.asarray(branches[s][0], np.float64)):
                contacts.append((m, s))
    return contacts


def guarded_move(branches, index: int, rotation=np.eye(3), pivot=(0.0, 0.0, 0.0),
                 translation=(0.0, 0.0, 0.0)) -> list:
    """`move_branches`, refused with MoveRefused when `move_contacts` finds the moved branches touching others."""
    moved = move_branches(branches, index, rotation, pivot, translation)
    contacts = move_contacts(branches, index, moved)
    if contacts:
        pairs = ", ".join(f"{m} with {s}" for m, s in contacts)
        raise MoveRefused(f"the move would make branches touch ({pairs}); allowed: a move that keeps the moved "
                          "branches' convex hulls apart from the others")
    return moved


def swipe_angle(before, after, centre=(0.0, 0.0)) -> float:
    """Radians, counter-clockwise positive: the turn of a thumb from `before` to `after` (2D pad or stick
    positions) about `centre` (eq. 4.1: theta = tau arccos of the cosine between P1 - u and P2 - u, tau the sign
    of their cross product's z; u = (127.5, 127.5) on the thesis's 256-pixel touchpad, (0, 0) on a thumbstick).
    0.0 when either position sits on the centre."""
    u = np.asarray(centre, np.float64).reshape(2)
    p1, p2 = np.asarray(before, np.float64).reshape(2) - u, np.asarray(after, np.float64).reshape(2) - u
    lengths = np.linalg.norm(p1) * np.linalg.norm(p2)
    if not np.isfinite(lengths):
        raise MoveRefused(f"swipe positions {np.asarray(before).tolist()} and {np.asarray(after).tolist()}; "
                          "allowed: finite 2D positions")
    if lengths < 1e-12:
        return 0.0
    cosine = float(np.clip(p1 @ p2 / lengths, -1.0, 1.0))
    tau = 1.0 if p1[0] * p2[1] - p1[1] * p2[0] >= 0 else -1.0
    return tau * float(np.arccos(cosine))
